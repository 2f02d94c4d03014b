"""The run config: one pydantic model for a whole training run, loaded from YAML.

Every section forbids unknown keys, so a typo fails with its path instead of silently running a
default:

    $ hcgym train --config bad.yaml
    hcgym train: error: bad.yaml: invalid config
      trainer.batch_sise: unknown key
      rollout.group_size: Input should be a valid integer (got 'three')

The package splits by job: `schema` (RunConfig and its sections; the learner-side sections are the
models of `modeling/config_models.py`), `loading` (YAML, `extends`, overrides, error lines) and
`checks` (numbers pydantic's lax mode lets through; domains, splits and paths the config names).
This module re-exports their public names.

A config may start from another with `extends: other.yaml` (path relative to the file); mappings
merge key by key, everything else is replaced. `--set key.path=value` overrides apply last.

Example:
    >>> cfg = load_config("configs/tiny_cpu_ttopd.yaml", overrides=["trainer.max_steps=3"])
    >>> cfg.trainer.max_steps
    3
"""

# _read_yaml: evals.policies reads a run folder's config.yaml with it.
from learner.config.loading import ConfigError, _read_yaml, dump_config, format_errors, load_config, validate_config
from learner.config.schema import (REMOVED_CORRECT_IF, DataConfig, DynamicSamplingConfig, GeneratorConfig, KBConfig,
                                   MetricsConfig, ModelConfig, RayConfig, RewardConfig, RolloutConfig, RunConfig,
                                   SFTConfig, TinyModelConfig, TrainerConfig)

# The sections the schema takes from the learner side, the actors and the planner.
from actors.agent_loop import RolloutLimits
from actors.generator import SamplingConfig
from modeling.config_models import (OFFPOLICY_TIS_CAP, ConfigModel, LearnerConfig, TeacherConfig,
                                   WeightSyncConfig)
from modeling.plan import ClusterConfig

__all__ = ["ConfigError", "DataConfig", "DynamicSamplingConfig", "GeneratorConfig", "KBConfig", "MetricsConfig",
           "ModelConfig", "REMOVED_CORRECT_IF", "RayConfig", "RewardConfig", "RolloutConfig", "RunConfig", "SFTConfig",
           "TinyModelConfig", "TrainerConfig", "dump_config", "format_errors", "load_config", "validate_config",
           "ClusterConfig", "ConfigModel", "LearnerConfig", "OFFPOLICY_TIS_CAP", "RolloutLimits", "SamplingConfig",
           "TeacherConfig", "WeightSyncConfig"]
