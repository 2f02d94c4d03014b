"""hcgym view: a local, read-only web page over training runs and evaluations (see README.md)."""
