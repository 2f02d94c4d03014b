"""`python -m envs.domains.cross_domain.authoring`: regenerate pathways.json and split_tasks.json."""

from . import write

if __name__ == "__main__":
    for path in write():
        print(f"wrote {path}")
