"""Bootstrap intervals against closed forms, and the paired comparison's sign on constructed cases."""

import numpy as np
import pytest
from scipy import stats

from vical.evaluation.intervals import bootstrap_mean, paired_difference, proportion


def test_binary_sample_matches_the_binomial_distribution_of_the_bootstrap_mean():
    # Resampling n values of which k are 1 gives a mean distributed as Binomial(n, k / n) / n: its 2.5 % and
    # 97.5 % quantiles are the exact percentile interval.
    n, k = 40, 10
    sample = np.r_[np.ones(k), np.zeros(n - k)]
    interval = bootstrap_mean(sample, resamples=20_000, seed=3)
    low, high = stats.binom.ppf([0.025, 0.975], n, k / n) / n
    assert interval.estimate == pytest.approx(0.25)
    assert interval.low == pytest.approx(low, abs=1.0 / n)  # one step of the discrete distribution
    assert interval.high == pytest.approx(high, abs=1.0 / n)


def test_large_normal_sample_gives_the_normal_interval():
    x = np.random.default_rng(0).normal(2.0, 3.0, 400)
    interval = bootstrap_mean(x, seed=1)
    half = 1.96 * x.std() / np.sqrt(len(x))
    assert interval.low == pytest.approx(x.mean() - half, abs=0.1 * half)
    assert interval.high == pytest.approx(x.mean() + half, abs=0.1 * half)


def test_constant_sample_and_seeding():
    interval = bootstrap_mean(np.full(7, 0.3))
    assert (interval.low, interval.estimate, interval.high) == pytest.approx((0.3, 0.3, 0.3))
    x = np.random.default_rng(2).normal(size=30)
    assert bootstrap_mean(x, seed=5) == bootstrap_mean(x, seed=5)
    with pytest.raises(ValueError, match="non-empty sample of finite values"):
        bootstrap_mean(np.array([1.0, np.nan]))


def test_paired_difference_sign_on_constructed_cases():
    rng = np.random.default_rng(4)
    reference = rng.lognormal(0.0, 1.0, 50)  # sensors differ 10x in difficulty
    better = reference * 0.9 + rng.normal(0, 0.01, 50)  # 10 % lower on every sensor
    worse = reference * 1.1
    assert paired_difference(better, reference).verdict == "lower"
    assert paired_difference(worse, reference).verdict == "higher"
    same = reference + rng.normal(0, 0.01, 50)
    assert paired_difference(same, reference).verdict == "no difference"
    # Unpaired, the 10 % gain would drown in the sensors' spread: pairing is what detects it.
    unpaired = bootstrap_mean(better).low < bootstrap_mean(reference).estimate < bootstrap_mean(better).high
    assert unpaired
    with pytest.raises(ValueError, match="same shape"):
        paired_difference(better[:3], reference)


@pytest.mark.parametrize(("successes", "trials"), [(44, 50), (1, 20), (19, 20), (132, 140)])
def test_proportion_interval_solves_the_binomial_tail_equations(successes, trials):
    # Clopper-Pearson: the low end is the rate at which k or more successes have probability 2.5 %,
    # the high end the rate at which k or fewer have 2.5 %.
    i = proportion(successes, trials)
    assert i.estimate == pytest.approx(successes / trials)
    assert stats.binom.sf(successes - 1, trials, i.low) == pytest.approx(0.025, abs=1e-9)
    assert stats.binom.cdf(successes, trials, i.high) == pytest.approx(0.025, abs=1e-9)


def test_proportion_interval_at_the_edges_has_the_closed_form():
    none, every = proportion(0, 10), proportion(10, 10)
    assert (none.low, every.high) == (0.0, 1.0)
    assert none.high == pytest.approx(1.0 - 0.025 ** (1 / 10))
    assert every.low == pytest.approx(0.025 ** (1 / 10))


def test_proportion_interval_covers_the_true_rate_at_least_at_its_level():
    rng = np.random.default_rng(3)
    for rate in (0.5, 0.9, 0.97):
        hits = rng.binomial(50, rate, size=2000)
        covered = [proportion(k, 50).low <= rate <= proportion(k, 50).high for k in hits]
        assert np.mean(covered) >= 0.94


@pytest.mark.parametrize(("successes", "trials"), [(3, 0), (-1, 5), (6, 5), (2.0, 5), (True, 5), (np.float64(2), 5)])
def test_proportion_rejects_counts_that_are_not_a_rate(successes, trials):
    with pytest.raises(ValueError, match="successes <= trials"):
        proportion(successes, trials)


def test_proportion_takes_numpy_counts_as_python_ones():
    stopped_right = np.array([True] * 44 + [False] * 6)
    assert proportion(stopped_right.sum(), np.int64(stopped_right.size)) == proportion(44, 50)
