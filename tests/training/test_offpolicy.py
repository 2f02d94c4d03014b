"""Off-policy correction (losses.py Eq. 1b-1d) through the config, the learner and a staleness-1 run.

The loss arithmetic itself is checked against hand-computed values in test_losses.py; here the
pieces around it: the default that turns it on, the learner's per-token lag (its own version count,
restored from checkpoints), and a real run on local Ray whose lagged tokens carry ratios != 1.
"""

from __future__ import annotations

import math

import pytest

from learner.config import validate_config
from modeling.config_models import OFFPOLICY_TIS_CAP, LearnerConfig
from learner.learner_actor import Learner
from learner.metrics import read_metrics, read_samples
from tests.training.learner_fixtures import make_batch, tiny_model_dir
from tests.training.test_train import tiny_config

IS_KEYS = ("is_ratio_mean", "is_ratio_max", "is_weight_mean", "is_capped_frac", "is_stale_frac", "is_lag_mean",
           "is_lag_max", "is_log_ratio_abs_stale", "is_log_ratio_abs_fresh", "kl_ref", "kl_ref_unweighted",
           "kl_ref_max")


def test_correction_defaults_on_with_staleness_and_stays_configurable():
    def grpo(staleness, **grpo_section):
        data = {"trainer": {"max_staleness": staleness}}
        if grpo_section:
            data["learner"] = {"loss": {"grpo": grpo_section}}
        return validate_config(data).learner.loss.grpo

    assert grpo(0).tis_cap is None                      # on-policy: unchanged
    assert grpo(1).tis_cap == OFFPOLICY_TIS_CAP         # stale tokens possible: on by default
    assert grpo(2, tis_cap=5.0).tis_cap == 5.0          # an explicit cap wins
    assert grpo(1, tis_cap=None).tis_cap is None        # and an explicit null keeps it off
    assert grpo(0, tis_cap=3.0).tis_cap == 3.0          # on-policy runs may still correct vLLM numerics
    # The resolved config (config.yaml of a run) reloads to the same value, also with the default.
    dumped = validate_config({"trainer": {"max_staleness": 1}}).model_dump(mode="json")
    assert validate_config(dumped).learner.loss.grpo.tis_cap == OFFPOLICY_TIS_CAP
    with pytest.raises(ValueError, match="tis_cap"):
        grpo(1, tis_cap=0.0)


def test_learner_lags_tokens_against_its_own_version_and_restores_it(tmp_path):
    model_dir = tiny_model_dir()
    batch = make_batch(seed=0, groups=2, group_size=3, model_dir=model_dir)  # sampled by version 0
    learner = Learner(LearnerConfig(optim={"lr": 2e-3}, loss={"grpo": {"tis_cap": 2.0}}), model_dir)
    m1 = learner.train_step(batch, step=1)
    # Version 0 trains on version-0 tokens: lag 0, ratios 1 up to float noise, weights 1.
    assert m1["is_stale_frac"] == 0.0 and m1["is_lag_max"] == 0.0
    assert m1["is_log_ratio_abs_fresh"] < 1e-5 and m1["is_weight_mean"] == pytest.approx(1.0, abs=1e-5)
    m2 = learner.train_step(batch, step=2)
    # Version 1 trains on the same version-0 tokens: every token lags by 1 and its ratio moved.
    assert m2["is_stale_frac"] == 1.0 and m2["is_lag_max"] == 1.0 and m2["is_lag_mean"] == 1.0
    assert m2["is_log_ratio_abs_stale"] > 1e-3
    assert m2["is_ratio_max"] > 1.0 and m2["is_weight_mean"] <= 2.0
    assert all(math.isfinite(m2[k]) for k in IS_KEYS)

    # A learner restored from the checkpoint counts from the saved version (2): lag 2.
    learner.save_checkpoint(str(tmp_path))
    restored = Learner(LearnerConfig(optim={"lr": 2e-3}, loss={"grpo": {"tis_cap": 2.0}}), model_dir)
    restored.load_checkpoint(str(tmp_path))
    m3 = restored.evaluate_loss(batch)
    assert m3["is_lag_max"] == 2.0 and m3["is_stale_frac"] == 1.0


@pytest.mark.ray
def test_staleness_one_run_trains_lagged_tokens_with_bounded_weights(ray_cluster, ward_policy_dir, tmp_path):
    from learner.train import train

    cfg = tiny_config(tmp_path / "stale", ward_policy_dir,
                      trainer={"max_steps": 3, "max_staleness": 1, "checkpoint_interval": 0})
    assert cfg.learner.loss.grpo.tis_cap == OFFPOLICY_TIS_CAP  # the default, not set by the test
    train(cfg, log=lambda line: None)
    records = read_metrics(cfg.output_dir)
    assert [r["step"] for r in records] == [1, 2, 3]
    stale_steps = 0
    for r in records:
        assert all(math.isfinite(r[k]) for k in IS_KEYS), r
        assert 0.0 < r["is_weight_mean"] <= OFFPOLICY_TIS_CAP and 0.0 <= r["is_capped_frac"] <= 1.0
        assert r["kl_ref"] <= r["kl_ref_max"] + 1e-12 and r["kl_ref_max"] < 10.0
        # The learner's lag (its own version count) is the driver's (from the token versions).
        assert r["is_lag_max"] == r["policy_lag_max"] <= 1
        samples, _ = read_samples(tmp_path / "stale" / "trajectories" / f"step_{r['step']:06d}.parquet")
        lags = [r["step"] - 1 - v for s in samples for v, m in zip(s.policy_versions, s.loss_mask) if m]
        assert r["is_stale_frac"] == pytest.approx(sum(lag > 0 for lag in lags) / len(lags))
        if r["is_stale_frac"] > 0:
            stale_steps += 1
            # Lagged tokens were sampled by other weights: their ratios are not 1, while lag-0
            # tokens differ from the generator's only by float noise.
            assert r["is_log_ratio_abs_stale"] > 1e-3, r
            assert r["is_log_ratio_abs_stale"] > 10 * r["is_log_ratio_abs_fresh"], r
    # The first (S + 1) x batch_size groups are admitted at version 0, so step 2 trains lag-1 tokens.
    assert stale_steps >= 1
