"""Safety checks, one module per concern; importing this package registers them all.

A check is a plain function `check(state: SafetyState) -> None` decorated with
`@safety_check`; it reads `state.view` (the episode) and `state.ctx` (domain facts) and calls
`state.emit(pattern_id, turn=..., evidence=..., key=...)`. See `envs/rewards/README.md`.
"""

from envs.rewards.checks import emergency, ethics, evidence, medication, workup  # noqa: F401
