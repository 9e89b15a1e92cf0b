"""Application functions: skills for specific applications, built from the core functions."""
