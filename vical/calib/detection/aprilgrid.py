"""Aprilgrid detection with point ids in Kalibr's numbering (``vical.data.Target``).

Tags are found with OpenCV's aruco module and its ``DICT_APRILTAG_36h11`` dictionary, reading a
2-bit black border as Kalibr's grids are printed; aruco's corner order is matched to Kalibr's on a
printed grid (``corner_order``), since OpenCV's AprilTag orientation differs between versions.
As in Kalibr's ``GridCalibrationTargetAprilgrid``: tags with an id outside the grid, tags seen
twice (a stray tag in the scene) and tags with a corner closer than ``min_border_px`` to the image
edge are dropped; the tag corners are refined with ``cv2.cornerSubPix`` (they are X-junctions with
the grid's black corner squares) and a corner the refinement moves out of its search window (or
cannot refine) is dropped. (Aruco's unrefined corners are contour vertices, about 2-3 px off at
these junctions, so Kalibr's 1.2 px displacement limit for its own detector's corners does not
transfer.) Partial views give the corners of the tags seen.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

from vical.calib.errors import CalibrationError
from vical.data.target import Target

_PROBE_PX_PER_BIT = 4  # the grid that ``corner_order`` detects to learn aruco's corner order
_PROBE_PAD_PX = 20
WINDOW_FRACTION = 0.75  # search half-window / (gap or black border, the smaller) [px / px]
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 40, 1e-3)


@functools.cache
def corner_order() -> np.ndarray:
    """(4,) ``order`` with aruco's corner ``order[j]`` = Kalibr's corner ``j`` of a tag as Kalibr prints it.

    Kalibr orders a tag's corners counter-clockwise from (min x, min y) on the print; aruco starts
    from its own marker image's top-left, and that image is Kalibr's print turned by an amount
    that changed between OpenCV versions. So the order is measured, once, by detecting a printed
    grid (``Target.aprilgrid_image``, Kalibr's orientation) whose corner pixels are known.
    """
    target = Target.aprilgrid(2, 2, 0.1, 0.3)
    image = np.pad(target.aprilgrid_image(_PROBE_PX_PER_BIT), _PROBE_PAD_PX, constant_values=255)
    quads, tag_ids, _ = make_aprilgrid_detector().detectMarkers(image)
    if tag_ids is None or 0 not in tag_ids:
        raise CalibrationError("aruco does not detect tag 0 of a printed aprilgrid; check the OpenCV installation")
    quad = np.asarray(quads[int(np.flatnonzero(np.ravel(tag_ids) == 0)[0])], dtype=float).reshape(4, 2)
    s = target.row_spacing / (10 * _PROBE_PX_PER_BIT)  # [m/px]
    margin = 2 * round(target.tag_spacing * 10 * _PROBE_PX_PER_BIT) + _PROBE_PAD_PX
    xy = target.points[target.tag_corner_ids([0])[0], :2]
    expected = np.stack([xy[:, 0] / s + margin - 0.5, image.shape[0] - xy[:, 1] / s - margin - 0.5], axis=1)
    order = np.argmin(np.linalg.norm(expected[:, None] - quad[None], axis=2), axis=1)
    if sorted(order.tolist()) != [0, 1, 2, 3]:
        raise CalibrationError(f"cannot match aruco's tag corners to Kalibr's order (got {order.tolist()})")
    return order


def make_aprilgrid_detector() -> cv2.aruco.ArucoDetector:
    """An aruco detector for tag36h11 tags with a 2-bit black border (Kalibr's print)."""
    params = cv2.aruco.DetectorParameters()
    params.markerBorderBits = 2
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    return cv2.aruco.ArucoDetector(dictionary, params)


def detect_aprilgrid(
    image: np.ndarray, target: Target, min_border_px: float = 4.0, detector: cv2.aruco.ArucoDetector | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Find the aprilgrid's tag corners in a grey image.

    Args:
        image: (H, W) uint8 grey image.
        target: an aprilgrid ``Target``.
        min_border_px: tags with a corner closer than this to the image edge are dropped [px].
        detector: a reusable ``make_aprilgrid_detector()`` (built per call when None).

    Returns:
        corners (K, 2) float64 [px] and ids (K,) int64 point ids, sorted by id; empty when no
        tag was found.
    """
    if target.kind != "aprilgrid":
        raise CalibrationError(f"detect_aprilgrid needs an aprilgrid target, got {target.kind!r}")
    if image.ndim != 2 or image.dtype != np.uint8:
        raise CalibrationError(f"detect_aprilgrid needs an (H, W) uint8 grey image, got {image.shape} {image.dtype}")
    quads, tag_ids, _ = (detector or make_aprilgrid_detector()).detectMarkers(image)
    if tag_ids is None:
        return np.zeros((0, 2)), np.zeros(0, dtype=np.int64)
    quads = np.asarray(quads, dtype=np.float64).reshape(-1, 4, 2)[:, corner_order()]
    tag_ids = np.asarray(tag_ids, dtype=np.int64).reshape(-1)
    keep = _valid_tags(quads, tag_ids, target, image.shape, min_border_px)
    quads, tag_ids = quads[keep], tag_ids[keep]
    if not len(tag_ids):
        return np.zeros((0, 2)), np.zeros(0, dtype=np.int64)
    corners, moved = _refine(image, quads, target)
    ids = target.tag_corner_ids(tag_ids).reshape(-1)
    good = ~moved
    order = np.argsort(ids[good])
    return corners[good][order], ids[good][order]


def _valid_tags(
    quads: np.ndarray, tag_ids: np.ndarray, target: Target, shape: tuple[int, ...], border: float
) -> np.ndarray:
    """(T,) mask of tags in the grid, seen once, with every corner ``border`` px inside the image."""
    in_grid = (tag_ids >= 0) & (tag_ids < target.num_tags)
    values, counts = np.unique(tag_ids, return_counts=True)
    unique = ~np.isin(tag_ids, values[counts > 1])
    h, w = shape
    u, v = quads[..., 0], quads[..., 1]
    inside = np.all((u >= border) & (u <= w - 1 - border) & (v >= border) & (v <= h - 1 - border), axis=1)
    return in_grid & unique & inside


def _refine(image: np.ndarray, quads: np.ndarray, target: Target) -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel corners (4T, 2) and a mask (4T,) of corners the refinement moved out of its window.

    Each tag's search window stays inside the smaller of the gap between tags and the tag's black
    border (0.2 tag sizes), measured on that tag's shortest side in the image: one window for all
    tags, sized by the smallest, left the corners of large tags at aruco's contour vertices
    (2-3 px off) whenever a partial or oblique view also held a small tag.
    """
    sides = np.min(np.linalg.norm(quads - np.roll(quads, 1, axis=1), axis=2), axis=1)  # (T,) [px]
    halves = np.clip(np.floor(WINDOW_FRACTION * sides * min(target.tag_spacing, 0.2)), 1, 8).astype(int)
    refined = quads.reshape(-1, 2).copy()
    moved = np.zeros(len(refined), dtype=bool)
    for half in np.unique(halves):
        rows = (np.flatnonzero(halves == half)[:, None] * 4 + np.arange(4)).ravel()
        raw = np.ascontiguousarray(quads.reshape(-1, 2)[rows], dtype=np.float32).reshape(-1, 1, 2)
        out = cv2.cornerSubPix(image, raw.copy(), (int(half), int(half)), (-1, -1), _SUBPIX_CRITERIA).reshape(-1, 2)
        shift = np.max(np.abs(out - raw.reshape(-1, 2)), axis=1)
        # cornerSubPix hands back the start point unchanged when its estimate leaves the window.
        moved[rows] = (shift > half) | (shift == 0.0)
        refined[rows] = out
    return refined.astype(np.float64), moved
