"""The arrays the containers are made of: int64 nanosecond timestamps and (N, 3) per-sample vectors.

Timestamps are ``int64`` nanoseconds everywhere (float seconds lose ns precision on epoch
times); convert to seconds only relative to a recording's start (``seconds_since``).
"""

from __future__ import annotations

import numpy as np

from vical.data.errors import DataError

NS_PER_S = 1_000_000_000


def median_rate_hz(t_ns: np.ndarray) -> float:
    """[Hz] a stream's rate from its median sample interval (robust to a few dropped samples); 0 for fewer than
    two stamps."""
    return float(NS_PER_S / np.median(np.diff(t_ns))) if len(t_ns) > 1 else 0.0


def seconds_since(t_ns: np.ndarray, t0_ns: int) -> np.ndarray:
    """Float seconds of int64 ns timestamps relative to ``t0_ns`` (exact to ~1e-16 s for short spans)."""
    return (np.asarray(t_ns, dtype=np.int64) - np.int64(t0_ns)).astype(np.float64) / NS_PER_S


def as_timestamps(t: np.ndarray, name: str) -> np.ndarray:
    """``t`` as int64 ns, checked: 1-D, integer, strictly increasing (``DataError`` naming ``name``)."""
    t = np.asarray(t)
    if t.ndim != 1:
        raise DataError(f"{name} must be a 1-D array of int64 ns timestamps, got shape {t.shape}")
    if t.size and not np.issubdtype(t.dtype, np.integer):
        raise DataError(f"{name} must hold integer nanoseconds (int64), got dtype {t.dtype}")
    t = t.astype(np.int64)
    if np.any(np.diff(t) <= 0):
        bad = int(np.argmax(np.diff(t) <= 0))
        raise DataError(f"{name} must be strictly increasing; sample {bad + 1} is not after sample {bad}")
    return t


def as_vectors(x: np.ndarray, n: int, name: str) -> np.ndarray:
    """``x`` as float64 ``(n, 3)``, checked: that shape, all finite (``DataError`` naming ``name``)."""
    x = np.asarray(x, dtype=np.float64)
    if x.shape != (n, 3):
        raise DataError(f"{name} must have shape ({n}, 3), got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise DataError(f"{name} contains NaN or inf")
    return x
