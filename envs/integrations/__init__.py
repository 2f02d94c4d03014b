"""Adapters that serve the gym's one episode core (`envs.env.HealthcareGymEnv`'s structured API) to
other frameworks. Each imports its framework only when used, so the package imports without them."""
