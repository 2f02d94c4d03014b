"""Evaluation harness: a policy on a suite under a condition, results in a Parquet folder.

See docs/evaluation.md (user guide) and evals/README.md (how to add a policy or a condition).
"""
