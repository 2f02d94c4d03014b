"""HealthcareGym for verifiers v1 (prime-rl, `vf-eval`, the Environments Hub): see taskset.py."""

from .taskset import HealthcareGymEnvironment, HealthcareGymTaskset

__all__ = ["HealthcareGymEnvironment", "HealthcareGymTaskset"]
