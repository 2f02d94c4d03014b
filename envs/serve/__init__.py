"""Serving the environment to agents and trainers outside the project (`hcgym serve`)."""
