"""Checkpoints of a run in SQLite and resuming a run after a crash from them."""
