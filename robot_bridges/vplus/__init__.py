"""vplus back end."""
