"""Checks of the samples read from files: timestamps, sampling, IMU units, camera rates.

Each check names the file (and line or topic) it found a problem in. Where the fix is
unambiguous it is applied with a ``FormatWarning`` (unsorted rows are sorted, exact duplicate
rows dropped, decimal-second timestamps converted to ns); otherwise a ``FormatError`` says what
to do.
"""

from __future__ import annotations

import warnings

import numpy as np

from vical.data import NS_PER_S, median_rate_hz
from vical.io.errors import FormatError, UnitError

# A plausible sample interval in ns: 10 kHz .. 0.1 Hz.
MIN_DT_NS, MAX_DT_NS = 100_000, 10 * NS_PER_S
# MEMS gyros saturate at about 2000 deg/s = 35 rad/s: larger readings are not rad/s.
MAX_GYRO_RAD_S = 35.0
# A calibration motion rotates faster than this somewhere (the calibrator needs rotation about two axes).
MIN_MOTION_RAD_S = 0.1
# The accelerometer's median norm is dominated by gravity (9.81 m/s^2).
ACCEL_NORM_RANGE = (4.0, 30.0)
GYRO_UNITS = {"rad/s": 1.0, "deg/s": np.pi / 180.0}
ACCEL_UNITS = {"m/s^2": 1.0, "g": 9.80665}


class FormatWarning(UserWarning):
    """A flaw in an input file that vical fixed (the message says which and how)."""


def warn(message: str) -> None:
    """Emit a ``FormatWarning`` attributed to the caller of the reader."""
    warnings.warn(message, FormatWarning, stacklevel=4)


def parse_timestamp_ns(text: str, where: str) -> tuple[int, bool]:
    """Exact int64 ns of a timestamp string, and whether it was written in decimal seconds.

    ``"1403636579763555584"`` is ns; ``"1403636579.763555584"`` is seconds and converted exactly
    (no float rounding).
    """
    text = text.strip()
    whole, dot, frac = text.partition(".")
    if not whole.lstrip("-").isdigit() or (dot and frac and not frac.isdigit()) or len(frac) > 9:
        raise FormatError(f"{where}: timestamp {text!r} is not an integer number of ns")
    if not dot:
        return int(whole), False
    sign = -1 if whole.startswith("-") else 1
    return int(whole) * NS_PER_S + sign * int(frac.ljust(9, "0") or "0"), True


def check_sampling(t: np.ndarray, where: str) -> None:
    """Raise when the median interval of ``t`` [ns] shows the timestamps are not in ns."""
    if len(t) < 2:
        return
    dt = np.diff(t)
    dt = dt[dt > 0]
    if not len(dt):
        return
    median = float(np.median(dt))
    if median < MIN_DT_NS:
        raise FormatError(
            f"{where}: median timestamp step is {median:g}, too small for ns (implying over 10 kHz); "
            "the timestamps look like seconds, ms or us: convert them to integer nanoseconds"
        )
    if median > MAX_DT_NS:
        raise FormatError(f"{where}: median timestamp step is {median:g} ns (over 10 s); are the timestamps in ns?")


def sort_and_dedupe(t: np.ndarray, rows: np.ndarray, where: str, lines: np.ndarray) -> np.ndarray:
    """Row order (indices) that sorts ``t`` and drops exact duplicate rows.

    Args:
        t: (N,) int64 [ns] timestamps as read.
        rows: (N, D) the data of each row (compared for duplicates).
        where: file (or topic) for messages; lines: (N,) line numbers (or message indices).
    Raises ``FormatError`` when two rows share a timestamp but differ (ambiguous).
    """
    order = np.argsort(t, kind="stable")
    if np.any(np.diff(t) < 0):
        bad = int(np.argmax(np.diff(t) < 0)) + 1
        warn(f"{where}: timestamps are not sorted (line {lines[bad]} is earlier than line {lines[bad - 1]}); sorted")
    ts, rs = t[order], rows[order]
    same = np.flatnonzero(np.diff(ts) == 0)
    conflicting = [i for i in same if not np.array_equal(rs[i], rs[i + 1])]
    if conflicting:
        i = conflicting[0]
        raise FormatError(
            f"{where}: lines {lines[order[i]]} and {lines[order[i + 1]]} share timestamp {ts[i]} ns with different "
            "data; remove one of them"
        )
    if len(same):
        example = lines[order[same[0] + 1]]
        warn(f"{where}: {len(same)} duplicated rows (same timestamp and data, e.g. line {example}) dropped")
        order = np.delete(order, same + 1)
    return order


def scale_imu(
    gyro: np.ndarray, accel: np.ndarray, gyro_unit: str, accel_unit: str, where: str
) -> tuple[np.ndarray, np.ndarray]:
    """Gyro [rad/s] and accel [m/s^2] from values in the given units.

    Raises ``UnitError`` naming the unit setting to change when the values fit another unit better.
    """
    if gyro_unit not in GYRO_UNITS or accel_unit not in ACCEL_UNITS:
        raise FormatError(f"gyro_unit must be one of {list(GYRO_UNITS)}, accel_unit one of {list(ACCEL_UNITS)}")
    gyro = gyro * GYRO_UNITS[gyro_unit]
    accel = accel * ACCEL_UNITS[accel_unit]
    if len(gyro) == 0:
        return gyro, accel
    _check_gyro_unit(float(np.max(np.abs(gyro))), gyro_unit, where)
    _check_accel_unit(float(np.median(np.linalg.norm(accel, axis=1))), accel_unit, where)
    return gyro, accel


def _check_gyro_unit(peak: float, unit: str, where: str) -> None:
    """The peak rate [rad/s] against the declared unit: beyond a MEMS gyro, or too slow only because of deg/s."""
    if peak > MAX_GYRO_RAD_S and unit == "deg/s":
        raise FormatError(
            f"{where}: gyro reads up to {np.degrees(peak):.0f} deg/s, beyond any MEMS gyro's range even in deg/s; "
            "check the gyro's unit and scale"
        )
    if peak > MAX_GYRO_RAD_S:
        raise UnitError(
            f"{where}: gyro reads up to {peak:.1f} rad/s, beyond any MEMS gyro's range; the data look like deg/s: "
            "convert to rad/s or pass {fix}",
            "gyro_unit", "'deg/s'", "deg/s",
        )  # fmt: skip
    as_written = np.degrees(peak)
    if unit == "deg/s" and peak < MIN_MOTION_RAD_S <= as_written:
        raise UnitError(
            f"{where}: read as deg/s, the gyro peaks at {as_written:.3g} deg/s, too slow a motion to calibrate "
            f"from, while {as_written:.3g} rad/s would be a calibration motion: the data look like rad/s; pass {{fix}}",
            "gyro_unit", "'rad/s'", "rad/s",
        )  # fmt: skip


def _check_accel_unit(norm: float, unit: str, where: str) -> None:
    """The median specific-force norm [m/s^2] against gravity: the unit that would make it about 9.81 m/s^2."""
    low, high = ACCEL_NORM_RANGE
    if low <= norm <= high:
        return
    as_written = norm / ACCEL_UNITS[unit]
    message = f"{where}: median accelerometer norm is {norm:.3g} m/s^2 (read as {unit}), not about 9.81 m/s^2"
    for other, scale in ACCEL_UNITS.items():
        if other != unit and low <= as_written * scale <= high:
            raise UnitError(f"{message}; the data look like {other}: pass {{fix}}", "accel_unit", repr(other), other)
    raise FormatError(f"{message}; check the accelerometer's unit and scale")


# Cameras of one rig whose frame rates differ by more than this fraction are named in a warning.
RATE_TOLERANCE = 0.01


def check_camera_rates(where: str, stamps: dict[str, np.ndarray]) -> None:
    """Warn when the cameras of one rig (timestamps [ns] by name) run at different frame rates."""
    rates = {name: median_rate_hz(t) for name, t in stamps.items() if len(t) > 1}
    if len(rates) < 2:
        return
    first, *others = rates.items()
    for name, rate in others:
        if abs(rate - first[1]) > RATE_TOLERANCE * first[1]:
            warn(
                f"{where}: {name} runs at {rate:.3g} Hz but {first[0]} at {first[1]:.3g} Hz; the cameras of one rig "
                "usually share a trigger: check that these streams belong together"
            )
