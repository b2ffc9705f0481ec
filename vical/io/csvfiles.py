"""CSV files: EuRoC's IMU ``data.csv`` and vical's corner observations.

IMU CSV (EuRoC/ASL ``imu0/data.csv``), one sample per line::

    #timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],...
    1403636579758555392,-0.0991,0.1445,0.0544,8.1167,-1.9238,-1.0865

Corner CSV, one detected target point per line (ids as Kalibr numbers them, ``vical.data.Target``)::

    #timestamp [ns],point_id,u [px],v [px]
    1403636579763555584,0,312.25,140.5

Rows of one frame share its timestamp. A row with point id ``-1`` and empty ``u, v`` marks a frame
without detections (vical writes them so that frame timestamps survive a round trip; other
tools may omit such frames). Floats are written with 17 significant digits (exact float64).
"""

from __future__ import annotations

import itertools
import os
from pathlib import Path

import numpy as np

from vical.data import CameraFrames, DataError, ImuSamples, Target
from vical.io.atomic import atomic_file
from vical.io.errors import CsvFormatError, EmptyCsvError, FormatError, read_text_file
from vical.io.sample_checks import check_sampling, parse_timestamp_ns, scale_imu, sort_and_dedupe, warn

IMU_HEADER = (
    "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
    "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]"
)
CORNER_HEADER = "#timestamp [ns],point_id,u [px],v [px]"
NO_DETECTION_ID = -1


def read_rows(path: str | os.PathLike, n_fields: int) -> tuple[list[list[str]], list[int]]:
    """Data rows (split on commas) and their 1-based line numbers; ``#`` lines and blank lines are skipped.

    A first line that is a header without ``#`` (its first field not a number) is skipped too.
    """
    path = Path(path)
    text = read_text_file(path, CsvFormatError)
    rows, lines = [], []
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#") or (not rows and not line[:1].isdigit() and line[:1] not in "-."):
            continue
        fields = [f.strip() for f in line.split(",")]
        if len(fields) != n_fields:
            raise CsvFormatError(
                f"{path}, line {number}: expected {n_fields} comma-separated fields, got {len(fields)}"
            )
        rows.append(fields)
        lines.append(number)
    if text and not text.endswith("\n") and rows:
        warn(f"{path}: the last line has no line end (truncated file?); line {lines[-1]} was read as is")
    return rows, lines


def require_rows(rows: list[list[str]], path: Path, what: str) -> None:
    """Raise ``EmptyCsvError`` naming the file when it holds no data rows (``what``: what a row would be)."""
    if not rows:
        raise EmptyCsvError(f"{path} holds no {what} (the file is empty or has only a header)")


def parse_times(rows: list[list[str]], lines: list[int], path: Path) -> np.ndarray:
    """(N,) int64 [ns] of the first field of every row; decimal seconds are converted with a warning."""
    t = np.empty(len(rows), dtype=np.int64)
    any_seconds = False
    for k, (row, line) in enumerate(zip(rows, lines, strict=True)):
        try:
            t[k], seconds = parse_timestamp_ns(row[0], f"{path}, line {line}")
        except FormatError as exc:
            raise CsvFormatError(str(exc)) from exc
        any_seconds |= seconds
    if any_seconds:
        warn(f"{path}: timestamps are written in decimal seconds; converted exactly to integer ns")
    return t


def parse_floats(rows: list[list[str]], lines: list[int], columns: slice, path: Path) -> np.ndarray:
    """(N, C) float64 of the given columns; raises naming the line of a non-number."""
    try:
        return np.array([[float(v) for v in row[columns]] for row in rows], dtype=np.float64).reshape(len(rows), -1)
    except ValueError:
        for row, line in zip(rows, lines, strict=True):
            try:
                [float(v) for v in row[columns]]
            except ValueError as exc:
                raise CsvFormatError(f"{path}, line {line}: {exc}") from exc
        raise


# ------------------------------------------------------------------------------------ IMU
def read_imu_csv(path: str | os.PathLike, gyro_unit: str = "rad/s", accel_unit: str = "m/s^2") -> ImuSamples:
    """IMU samples from an EuRoC-style CSV (timestamp ns, gyro xyz, accel xyz).

    Unsorted rows are sorted and exact duplicates dropped (with a warning); conflicting
    duplicates and timestamps that are not ns raise ``CsvFormatError`` naming the file and line, a
    file without samples ``EmptyCsvError``, readings that fit another unit ``UnitError``.
    """
    path = Path(path)
    rows, lines = read_rows(path, 7)
    require_rows(rows, path, "IMU samples")
    t = parse_times(rows, lines, path)
    values = parse_floats(rows, lines, slice(1, 7), path)
    if not np.all(np.isfinite(values)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(values), axis=1))[0])
        raise CsvFormatError(f"{path}, line {lines[bad]}: NaN or inf reading")
    try:
        order = sort_and_dedupe(t, values, str(path), np.asarray(lines))
        check_sampling(t[order], str(path))
    except (FormatError, DataError) as exc:
        raise CsvFormatError(str(exc)) from exc
    gyro, accel = scale_imu(values[order, :3], values[order, 3:], gyro_unit, accel_unit, str(path))
    return ImuSamples(t[order], gyro, accel)


def write_imu_csv(imu: ImuSamples, path: str | os.PathLike) -> None:
    """Write ``imu`` as an EuRoC-style CSV (exact: int ns, 17 significant digits), atomically."""
    with atomic_file(path) as tmp, open(tmp, "w", encoding="utf-8") as f:
        f.write(IMU_HEADER + "\n")
        f.write(imu_rows(imu))


def imu_rows(imu: ImuSamples) -> str:
    """The IMU CSV's lines of ``imu`` (each ending in a newline), without the header."""
    rows = zip(imu.t.tolist(), imu.gyro.tolist(), imu.accel.tolist(), strict=True)
    return "".join(f"{t}," + ",".join(f"{v:.17g}" for v in (*g, *a)) + "\n" for t, g, a in rows)


# ------------------------------------------------------------------------------------ corners
def write_corners_csv(frames: CameraFrames, path: str | os.PathLike) -> None:
    """Write the detections of ``frames`` as a corner CSV (one row per point), atomically."""
    with atomic_file(path) as tmp, open(tmp, "w", encoding="utf-8") as f:
        f.write(CORNER_HEADER + "\n")
        for t, corners, ids in zip(frames.t.tolist(), frames.corners, frames.ids, strict=True):
            f.write(corner_rows(t, corners, ids))


def corner_rows(t: int, corners: np.ndarray, ids: np.ndarray) -> str:
    """The corner CSV's lines of one frame stamped ``t`` [ns] (a no-detection line when ``ids`` is empty)."""
    if not len(ids):
        return f"{t},{NO_DETECTION_ID},,\n"
    return "".join(f"{t},{i},{u:.17g},{v:.17g}\n" for i, (u, v) in zip(ids.tolist(), corners.tolist(), strict=True))


def read_corners_csv(path: str | os.PathLike, target: Target) -> CameraFrames:
    """Camera frames (detections only, no images) from a corner CSV.

    Raises ``CsvFormatError`` naming the line for point ids outside the target, a point listed
    twice in one frame, or non-numeric fields (``EmptyCsvError`` for a file without rows). Rows out
    of time order are sorted (warning).
    """
    path = Path(path)
    rows, lines = read_rows(path, 4)
    require_rows(rows, path, "corner rows")
    t = parse_times(rows, lines, path)
    ids = _parse_ids(rows, lines, target, path)
    detected = ids != NO_DETECTION_ID
    uv = np.full((len(rows), 2), np.nan)
    kept = np.flatnonzero(detected)
    uv[detected] = parse_floats([rows[k] for k in kept], [lines[k] for k in kept], slice(2, 4), path)
    if np.any(np.diff(t) < 0):
        line = lines[int(np.argmax(np.diff(t) < 0)) + 1]
        warn(f"{path}: rows are not in time order (line {line} is earlier than the line before); sorted")
    order = np.argsort(t, kind="stable")
    t, ids, uv, line_arr = t[order], ids[order], uv[order], np.asarray(lines)[order]
    frame_t, starts = np.unique(t, return_index=True)
    try:
        check_sampling(frame_t, str(path))
    except FormatError as exc:
        raise CsvFormatError(str(exc)) from exc
    bounds = [*starts.tolist(), len(t)]
    corners, frame_ids = [], []
    for a, b in itertools.pairwise(bounds):
        keep = ids[a:b] != NO_DETECTION_ID
        _check_unique(ids[a:b][keep], line_arr[a:b][keep], path)
        corners.append(uv[a:b][keep])
        frame_ids.append(ids[a:b][keep])
    return CameraFrames(frame_t, corners, frame_ids)


def _parse_ids(rows: list[list[str]], lines: list[int], target: Target, path: Path) -> np.ndarray:
    ids = np.empty(len(rows), dtype=np.int64)
    for k, (row, line) in enumerate(zip(rows, lines, strict=True)):
        if not row[1].lstrip("-").isdigit():
            raise CsvFormatError(f"{path}, line {line}: point id {row[1]!r} is not an integer")
        ids[k] = int(row[1])
        if ids[k] == NO_DETECTION_ID and (row[2] or row[3]):
            raise CsvFormatError(f"{path}, line {line}: point id -1 (no detection) must have empty u, v")
        if not NO_DETECTION_ID <= ids[k] < target.num_points:
            raise CsvFormatError(
                f"{path}, line {line}: point id {ids[k]} is outside the target's ids 0..{target.num_points - 1} "
                f"({target.kind} {target.rows} x {target.cols}); is it the right target file?"
            )
    return ids


def _check_unique(ids: np.ndarray, lines: np.ndarray, path: Path) -> None:
    values, counts = np.unique(ids, return_counts=True)
    if np.any(counts > 1):
        k = int(np.argmax(counts > 1))
        dup = np.flatnonzero(ids == values[k])
        raise CsvFormatError(
            f"{path}: lines {lines[dup[0]]} and {lines[dup[1]]} list point {values[k]} twice in one frame"
        )
