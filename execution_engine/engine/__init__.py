"""The execution engine: runs an application's operations over the group machines."""
