"""Paired comparisons of two policies over the same sensors: bootstrap confidence intervals.

Two policies evaluated on the same sensor seeds give one paired difference per sensor
``d_i = e_policy,i - e_reference,i`` (errors in %). The mean difference's 95 % confidence interval
is the percentile bootstrap over sensors: resample the n differences with replacement, take the
mean, repeat, and read the 2.5 % and 97.5 % quantiles. Pairing removes the sensor-to-sensor spread
that both policies share (a hard sensor is hard for both), which is what lets a few dozen sensors
separate policies whose errors overlap. The resampling is seeded, so a table is reproducible.

A rate over episodes (how often a stop was right) gets the exact binomial (Clopper-Pearson)
interval: 44 right stops of 50 read 88 %, but any rate from 76 to 95 % explains them.
"""

from __future__ import annotations

import numbers
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from scipy.stats import beta

RESAMPLES = 10_000
LEVEL = 0.95
# Fewest paired sensors an interval is given for: a bootstrap over one sensor reads [x, x], over a few it is far
# narrower than the truth's spread (the percentile bootstrap's coverage collapses below about 5).
MIN_SENSORS = 5


@dataclass(frozen=True)
class Interval:
    """A point estimate and its confidence interval.

    Attributes:
        estimate: the statistic on the data.
        low, high: the interval's ends.
        level: its confidence level (0.95).
    """

    estimate: float
    low: float
    high: float
    level: float

    @property
    def verdict(self) -> str:
        """``lower`` / ``higher`` when the interval excludes zero on that side, else ``no difference``."""
        if self.high < 0.0:
            return "lower"
        if self.low > 0.0:
            return "higher"
        return "no difference"


def bootstrap_mean(values: np.ndarray, level: float = LEVEL, resamples: int = RESAMPLES, seed: int = 0) -> Interval:
    """Percentile-bootstrap confidence interval of the mean of ``values`` (n,).

    Raises ``ValueError`` for an empty or non-finite sample.
    """
    x = np.asarray(values, dtype=float).reshape(-1)
    if not len(x) or not np.all(np.isfinite(x)):
        raise ValueError(f"bootstrap_mean needs a non-empty sample of finite values, got {len(x)} values")
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level}")
    rng = np.random.default_rng(seed)
    means = x[rng.integers(0, len(x), size=(resamples, len(x)))].mean(axis=1)
    tail = 100.0 * (1.0 - level) / 2.0
    low, high = np.percentile(means, [tail, 100.0 - tail])
    return Interval(float(x.mean()), float(low), float(high), level)


def paired_difference(
    policy: np.ndarray, reference: np.ndarray, level: float = LEVEL, resamples: int = RESAMPLES, seed: int = 0
) -> Interval:
    """Bootstrap interval of the mean of ``policy - reference`` (n,) paired by sensor.

    A negative interval (``verdict == "lower"``) means the policy's error is significantly lower.
    """
    a, b = np.asarray(policy, dtype=float), np.asarray(reference, dtype=float)
    if a.shape != b.shape:
        raise ValueError(f"paired samples must have the same shape, got {a.shape} and {b.shape}")
    return bootstrap_mean(a - b, level, resamples, seed)


def paired_by_sensor(policy: Mapping[int, float], reference: Mapping[int, float]) -> Interval | None:
    """``paired_difference`` of two policies' values by sensor seed (``{seed: value}``); None unless both hold the
    same sensors, at least ``MIN_SENSORS`` of them, every value finite."""
    if set(policy) != set(reference) or len(policy) < MIN_SENSORS:
        return None
    seeds = sorted(policy)
    mine, theirs = np.array([policy[s] for s in seeds]), np.array([reference[s] for s in seeds])
    if not (np.all(np.isfinite(mine)) and np.all(np.isfinite(theirs))):
        return None
    return paired_difference(mine, theirs)


def _is_count(n) -> bool:
    """A whole number of episodes: a Python or NumPy integer (a count summed with numpy is one), not a bool."""
    return isinstance(n, numbers.Integral) and not isinstance(n, bool)


def proportion(successes: int, trials: int, level: float = LEVEL) -> Interval:
    """Exact binomial (Clopper-Pearson) interval of a rate: ``successes`` of ``trials``.

    It covers the true rate with at least ``level`` probability for any rate, also at 0 or ``trials``
    successes, where a normal approximation collapses to a point.
    """
    if not (_is_count(trials) and _is_count(successes) and 0 <= successes <= trials and trials > 0):
        raise ValueError(
            f"proportion needs whole counts 0 <= successes <= trials and trials > 0, got {successes} of {trials}"
        )
    successes, trials = int(successes), int(trials)
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level}")
    tail = (1.0 - level) / 2.0
    low = 0.0 if successes == 0 else float(beta.ppf(tail, successes, trials - successes + 1))
    high = 1.0 if successes == trials else float(beta.ppf(1.0 - tail, successes + 1, trials - successes))
    return Interval(successes / trials, low, high, level)
