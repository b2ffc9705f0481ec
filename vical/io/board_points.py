"""Corner detections that name the board point by its board coordinates, as other calibrators write them.

Many tools (YAC, and any pipeline that keeps the object points beside the image points, as OpenCV's
``calibrateCamera`` takes them) write a detection as its pixel and its point on the board in metres,
not as a point id. Two layouts are read:

- a **corner CSV with named columns** (one file, rows of every frame): a header line naming at least
  a timestamp column (``ts``, ``timestamp`` or ``#timestamp [ns]``), the pixel (``kp_x, kp_y`` or
  ``u, v``) and the board point (``p_x, p_y, p_z``);
- a **corner folder**: ``camN/<timestamp ns>.csv`` per frame with the same columns (a file with only
  its header is a frame without detections) and the IMU beside them as ``imu0.csv`` (EuRoC's
  columns). YAC's test data and the real dev set are laid out so.

Each board point is matched to the target's point id (``vical.data.Target``) by its position. A
point that is no point of the target, or per-row ``tag_rows``, ``tag_cols``, ``tag_size``,
``tag_spacing`` columns that disagree with the target, mean the wrong target file: one line says so
with what the file holds.
"""

from __future__ import annotations

import functools
import itertools
import os
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import scipy.spatial

from vical.data import CameraFrames, Target
from vical.io.csvfiles import parse_floats, parse_times
from vical.io.errors import CsvFormatError, FormatError, SourceSettingError, read_text_file
from vical.io.sample_checks import check_sampling

TIME_COLUMNS = ("ts", "timestamp", "timestamp [ns]", "t_ns")
PIXEL_COLUMNS = (("kp_x", "kp_y"), ("u", "v"))
BOARD_COLUMNS = ("p_x", "p_y", "p_z")
# A board point matches a target point this close, as a fraction of the target's point spacing
# (files write board coordinates with 6 decimals; a wrong tag size moves points by whole percent).
MATCH_TOLERANCE = 1e-3
CAMERA_FOLDER = re.compile(r"cam(\d+)")
IMU_FILES = ("imu0.csv", "imu0/data.csv")


def column_names(header: str) -> list[str]:
    """The lower-case column names of a CSV header line (``#`` and unit brackets allowed)."""
    names = [n.strip().lower() for n in header.lstrip("#").split(",")]
    return [re.sub(r"\s*\[[^\]]*\]$", "", n) for n in names]


def has_board_points(header: str) -> bool:
    """Whether a CSV header names the board coordinates ``p_x, p_y, p_z`` of each corner."""
    return set(BOARD_COLUMNS) <= set(column_names(header))


def names_board_points(path: str | os.PathLike) -> bool:
    """Whether the CSV file's header (its first line) names the board coordinates of each corner."""
    with open(path, encoding="utf-8", errors="replace") as f:
        return has_board_points(f.readline())


class _Layout:
    """Where the timestamp, the pixel and the board point sit in a header's columns."""

    def __init__(self, header: str, path: Path) -> None:
        names = column_names(header)
        self.count = len(names)
        self.time = next((names.index(n) for n in TIME_COLUMNS if n in names), None)
        pixel = next((p for p in PIXEL_COLUMNS if set(p) <= set(names)), None)
        missing = [n for n in BOARD_COLUMNS if n not in names]
        if pixel is None or missing or self.time is None:
            raise CsvFormatError(
                f"{path}: a corner file with board coordinates needs the columns ts, kp_x, kp_y (or u, v) and p_x, "
                f"p_y, p_z; its header names {names}"
            )
        self.pixel = [names.index(n) for n in pixel]
        self.board = [names.index(n) for n in BOARD_COLUMNS]
        self.grid = {n: names.index(n) for n in ("tag_rows", "tag_cols", "tag_size", "tag_spacing") if n in names}


def _rows(path: Path) -> tuple[str, list[list[str]], list[int]]:
    """The header line, the data rows split on commas and their 1-based line numbers."""
    lines = read_text_file(path, CsvFormatError).splitlines()
    if not lines:
        raise CsvFormatError(f"{path} is empty; a corner file starts with a header naming its columns")
    rows, numbers = [], []
    for number, line in enumerate(lines[1:], start=2):
        if line.strip():
            rows.append([f.strip() for f in line.split(",")])
            numbers.append(number)
    return lines[0], rows, numbers


@functools.cache
def _point_tree(target: Target) -> scipy.spatial.cKDTree:
    return scipy.spatial.cKDTree(target.points)


def point_ids(board: np.ndarray, target: Target, where: str) -> np.ndarray:
    """(N,) target point ids of board points (N, 3) [m]; raises naming the first point the target lacks."""
    spacing = min(target.row_spacing, target.col_spacing)
    distance, ids = _point_tree(target).query(board)
    far = distance > MATCH_TOLERANCE * spacing
    if far.any():
        x, y, z = board[int(np.argmax(far))]
        raise CsvFormatError(
            f"{where}: board point ({x:g}, {y:g}, {z:g}) m is no point of the target ({_describe(target)}); "
            "give the --target the detections were made with"
        )
    return ids


def _describe(target: Target) -> str:
    if target.kind == "aprilgrid":
        size = f"tag size {target.row_spacing:g} m, spacing {target.tag_spacing:g}"
        return f"aprilgrid {target.rows} x {target.cols}, {size}"
    return f"checkerboard {target.rows} x {target.cols} inner corners, {target.row_spacing:g} m squares"


def _check_grid(rows: list[list[str]], layout: _Layout, target: Target, where: str) -> None:
    """Refuse per-row grid columns (``tag_rows`` ...) that describe another target than ``target``."""
    if not rows or target.kind != "aprilgrid":
        return
    expected = {"tag_rows": target.rows, "tag_cols": target.cols, "tag_size": target.row_spacing,
                "tag_spacing": target.tag_spacing}  # fmt: skip
    for name, column in layout.grid.items():
        try:
            value = float(rows[0][column])
        except ValueError:
            raise CsvFormatError(f"{where}: {name} {rows[0][column]!r} is not a number") from None
        if not np.isclose(value, expected[name], rtol=1e-6, atol=1e-9):
            raise CsvFormatError(
                f"{where}: the detections were made on a board with {name} {value:g}, but the target is "
                f"{_describe(target)}; give the --target of that board"
            )


def _detections(rows, numbers, layout: _Layout, target: Target, path: Path):
    """Times (N,) int64, pixels (N, 2) and point ids (N,) of the rows."""
    bad = next((n for r, n in zip(rows, numbers, strict=True) if len(r) != layout.count), None)
    if bad is not None:
        raise CsvFormatError(f"{path}, line {bad}: expected {layout.count} comma-separated fields as in the header")
    _check_grid(rows, layout, target, str(path))
    # the rows of a frame share one stamp: each distinct one is parsed once
    stamps, first, inverse = np.unique([r[layout.time] for r in rows], return_index=True, return_inverse=True)
    t = parse_times([[s] for s in stamps.tolist()], [numbers[k] for k in first], path)[inverse.ravel()]
    uv = parse_floats([[r[c] for c in layout.pixel] for r in rows], numbers, slice(0, 2), path)
    board = parse_floats([[r[c] for c in layout.board] for r in rows], numbers, slice(0, 3), path)
    if not (np.isfinite(uv).all() and np.isfinite(board).all()):
        raise CsvFormatError(f"{path}: NaN or inf in a corner's pixel or board coordinates")
    return t, uv, point_ids(board, target, str(path))


def _frame(uv: np.ndarray, ids: np.ndarray, where: str) -> tuple[np.ndarray, np.ndarray]:
    """One frame's corners and ids sorted by id; a point listed twice is refused."""
    order = np.argsort(ids, kind="stable")
    ids, uv = ids[order], uv[order]
    twice = np.flatnonzero(np.diff(ids) == 0)
    if len(twice):
        raise CsvFormatError(f"{where}: target point {ids[twice[0]]} is listed twice in one frame")
    return uv, ids


def read_board_point_csv(path: str | os.PathLike, target: Target) -> CameraFrames:
    """Camera frames from one corner CSV with named columns (board coordinates per corner)."""
    path = Path(path)
    header, rows, numbers = _rows(path)
    if not rows:
        raise CsvFormatError(f"{path} holds no corner rows (only its header)")
    t, uv, ids = _detections(rows, numbers, _Layout(header, path), target, path)
    order = np.argsort(t, kind="stable")
    t, uv, ids = t[order], uv[order], ids[order]
    frame_t, starts = np.unique(t, return_index=True)
    bounds = [*starts.tolist(), len(t)]
    frames = [_frame(uv[a:b], ids[a:b], f"{path}, frame {t[a]}") for a, b in itertools.pairwise(bounds)]
    check_sampling(frame_t, str(path))
    return CameraFrames(frame_t, [f[0] for f in frames], [f[1] for f in frames])


# ------------------------------------------------------------------------------------ corner folder
def camera_folders(root: Path) -> list[str]:
    """``cam0``, ``cam1``, ... folders of ``root`` that hold per-frame CSVs, in camera order."""
    found = sorted(
        (int(m.group(1)), p.name)
        for p in root.iterdir()
        if p.is_dir() and (m := CAMERA_FOLDER.fullmatch(p.name)) and any(p.glob("*.csv"))
    )
    return [name for _, name in found]


def chosen_cameras(
    available: list[str], requested: Sequence[str] | None, where: str, folders: str = "its camN folders"
) -> list[str]:
    """The camera folders of a recording to read: all of ``available`` (None), else its first camera (a
    recording's frames are its first camera's) and the ``requested`` ones; a requested camera it lacks is
    refused naming those it has.

    Reading only these spares decoding, detecting and parsing the others' frames (a stereo recording
    calibrated for cam0 read cam1's 720 corner files too: 0.3 s of the command's 2.3 s)."""
    if requested is None:
        return list(available)
    missing = [n for n in requested if n not in available]
    if missing:
        raise SourceSettingError(
            f"{{fix}} names {missing[0]}, but {where} has {', '.join(available)} ({folders}); "
            "name cameras it has",
            "cameras", None, None,
        )  # fmt: skip
    return [n for n in available if n == available[0] or n in requested]


def is_corner_folder(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a folder whose ``cam0/`` holds per-frame corner CSVs with board coordinates."""
    cam0 = Path(path) / "cam0"
    first = next(iter(sorted(cam0.glob("*.csv"))), None) if cam0.is_dir() else None
    return first is not None and names_board_points(first)


def corner_folder_imu(root: Path) -> Path | None:
    """The folder's IMU CSV (``imu0.csv`` or ``imu0/data.csv``), or None."""
    return next((root / n for n in IMU_FILES if (root / n).is_file()), None)


def read_camera_folder(folder: Path, target: Target) -> CameraFrames:
    """A camera's frames from its per-frame CSVs (``<timestamp ns>.csv``; one with only its header: no detection)."""
    files = sorted(folder.glob("*.csv"), key=lambda p: (len(p.stem), p.stem))
    stamps, corners, ids = [], [], []
    for path in files:
        if not path.stem.isdigit():
            raise FormatError(f"{path}: a corner folder's frame files are named by their timestamp in ns")
        stamps.append(int(path.stem))
        uv, point = _frame_file(path, target)
        corners.append(uv)
        ids.append(point)
    t = np.array(stamps, dtype=np.int64)
    check_sampling(t, str(folder))
    return CameraFrames(t, corners, ids)


def _frame_file(path: Path, target: Target) -> tuple[np.ndarray, np.ndarray]:
    """One frame file's corners (K, 2) and point ids (K,).

    The numbers are parsed in one go (a real recording has hundreds of files of ~130 rows); a file that does
    not parse so, or whose rows are not all stamped as its name says, is read row by row for the message that
    names the line."""
    text = read_text_file(path, CsvFormatError)
    header, _, body = text.partition("\n")
    lines = [line for line in body.split("\n") if line.strip()]
    if not lines:
        return np.zeros((0, 2)), np.zeros(0, np.int64)
    layout = _Layout(header, path)
    stamp = path.stem
    values = None
    if layout.time == 0 and all(line.startswith(stamp + ",") for line in lines):
        try:
            values = np.fromstring(",".join(lines), sep=",")  # the C parser, one pass
        except ValueError:  # a field that is no number: the rows say which
            values = None
        if values is not None and (values.size != len(lines) * layout.count or not np.isfinite(values).all()):
            values = None
    if values is None:
        return _frame_file_by_rows(path, target, int(stamp))
    values = values.reshape(len(lines), layout.count)
    _check_grid([[repr(float(v)) for v in values[0]]], layout, target, str(path))
    uv, board = values[:, layout.pixel], values[:, layout.board]
    return _frame(uv, point_ids(board, target, str(path)), str(path))


def _frame_file_by_rows(path: Path, target: Target, stamp: int) -> tuple[np.ndarray, np.ndarray]:
    header, rows, numbers = _rows(path)
    t, uv, point = _detections(rows, numbers, _Layout(header, path), target, path)
    if np.any(t != stamp):
        raise CsvFormatError(f"{path}: its rows are stamped {t[0]} ns, its name says {stamp} ns")
    return _frame(uv, point, str(path))
