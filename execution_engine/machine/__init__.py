"""The group machine: one SMACH-style state machine per robot group (paper Tables 1 and 2)."""
