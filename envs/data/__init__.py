"""The data build: real public data from registry packages, fetched, extracted, provenance kept."""
