"""Model code shared by the learner and the actors (generators, teacher).

Building and loading policies (`model`, `hf_checkpoint`), run-checkpoint files (`checkpoint`),
moving weights between processes (`weight_sync`) and the settings of the learner, teacher and
weight sync (`config_models`). It imports neither `learner` nor `actors`, so both can depend on it
and dependencies point one way: envs, kb_service <- modeling <- actors <- learner.
"""
