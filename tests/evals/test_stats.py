"""evals.stats against hand-computed values and scipy.stats (installed in .venv)."""

import numpy as np
import pytest
from scipy import stats as scipy_stats

from evals.stats import binomial_cdf_half, bootstrap_ci, bootstrap_means, mcnemar_exact, paired_bootstrap_ci


def test_bootstrap_ci_contains_the_mean_and_is_seeded():
    values = np.array([1, 0, 1, 1, 0, 1, 1, 1, 0, 1] * 5, dtype=float)  # 35/50 = 0.7
    first = bootstrap_ci(values, seed=3)
    assert first.estimate == pytest.approx(0.7) and first.n == 50
    assert first.low < 0.7 < first.high
    assert bootstrap_ci(values, seed=3) == first  # same seed, same interval
    assert not np.array_equal(bootstrap_means(values, seed=3), bootstrap_means(values, seed=4))
    # the normal approximation of a proportion's 95% CI: 0.7 +- 1.96 * sqrt(0.7 * 0.3 / 50) = [0.573, 0.827]
    assert first.low == pytest.approx(0.573, abs=0.03) and first.high == pytest.approx(0.827, abs=0.03)


def test_bootstrap_ci_is_the_percentile_of_resampled_means():
    values = np.array([0.2, 0.9, 0.4, 0.4, 1.0, 0.0, 0.7])
    means = bootstrap_means(values, n_resamples=2000, seed=11)
    # the same draw by hand: one integer matrix of indices from the same generator
    idx = np.random.default_rng(11).integers(0, values.size, size=(2000, values.size))
    np.testing.assert_allclose(means, values[idx].mean(axis=1))
    interval = bootstrap_ci(values, n_resamples=2000, seed=11)
    assert (interval.low, interval.high) == tuple(np.quantile(means, [0.025, 0.975]))


def test_bootstrap_ci_edge_cases_and_bad_input():
    constant = bootstrap_ci([1.0, 1.0, 1.0])
    assert (constant.estimate, constant.low, constant.high) == (1.0, 1.0, 1.0)
    with pytest.raises(ValueError, match="no items"):
        bootstrap_ci([])
    with pytest.raises(ValueError, match="NaN"):
        bootstrap_ci([0.5, float("nan")])
    with pytest.raises(ValueError, match="confidence"):
        bootstrap_ci([0.0, 1.0], confidence=95)
    with pytest.raises(ValueError, match="same length"):
        paired_bootstrap_ci([1, 0, 1], [1, 0])


def test_paired_bootstrap_is_narrower_than_unpaired_when_items_drive_the_score():
    rng = np.random.default_rng(0)
    difficulty = rng.uniform(0, 1, 200)
    a = difficulty + 0.05
    b = difficulty
    paired = paired_bootstrap_ci(a, b)
    assert paired.estimate == pytest.approx(0.05)
    assert paired.low == pytest.approx(0.05) and paired.high == pytest.approx(0.05)  # every item differs by 0.05
    # pairing matters: the arms' own intervals overlap heavily although the difference is certain
    assert bootstrap_ci(a).low < bootstrap_ci(b).high


def test_mcnemar_hand_computed():
    # 3 A-only, 0 B-only: p = 2 * P(X <= 0 | n=3) = 2 / 8
    a = [1, 1, 1, 1, 0]
    b = [1, 0, 0, 0, 0]
    result = mcnemar_exact(a, b)
    assert (result.a_only, result.b_only, result.both, result.neither) == (3, 0, 1, 1)
    assert result.p_value == pytest.approx(0.25)
    # no discordant pairs: no evidence of a difference
    assert mcnemar_exact([1, 0], [1, 0]).p_value == 1.0
    # 5 vs 5 discordant: two-sided p capped at 1
    assert mcnemar_exact([1] * 5 + [0] * 5, [0] * 5 + [1] * 5).p_value == 1.0
    assert binomial_cdf_half(1, 4) == pytest.approx(5 / 16)
    with pytest.raises(ValueError, match="boolean"):
        mcnemar_exact([2, 0], [1, 0])


@pytest.mark.parametrize("a_only,b_only", [(12, 3), (1, 9), (20, 20), (40, 25), (0, 7)])
def test_mcnemar_matches_scipy_binomtest(a_only, b_only):
    a = np.array([True] * a_only + [False] * b_only + [True] * 4 + [False] * 6)
    b = np.array([False] * a_only + [True] * b_only + [True] * 4 + [False] * 6)
    expected = scipy_stats.binomtest(min(a_only, b_only), a_only + b_only, 0.5, alternative="two-sided").pvalue
    assert mcnemar_exact(a, b).p_value == pytest.approx(expected, rel=1e-12)
