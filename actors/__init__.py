"""actors package."""
import envs._runtime  # noqa: F401  (CPU-path environment defaults)
