"""Clinical domains. The contract every domain follows is in README.md beside this file."""
