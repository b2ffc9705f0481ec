"""A hint when the images show a checkerboard of another size than the target given.

A board given with one row or column too many is found in no image; one given with one too few is
found in none or as a sub-grid in some (OpenCV's detector needs the exact count of inner corners).
Either way views are lost without a word. ``board_size_hint`` looks at a few sample images with
OpenCV's sector-based detector (``findChessboardCornersSB`` with ``CALIB_CB_LARGER``: it grows the
grid to the whole board, whatever its size) and names the size they show when it is not the given one.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from vical.calib.detection.checkerboard import FIND_FLAGS
from vical.data import Target

MAX_SAMPLE = 8  # images searched, about 25 ms each at 640 x 480
MAX_WIDTH = 1024  # [px] larger images are scaled down for the search (the grid is found as well)
MIN_IMAGES = 2  # a size must be found in this many sampled images (all of them, if fewer) to be suggested
SEED_PATTERN = (3, 3)  # the smallest grid the search starts from; CALIB_CB_LARGER grows it to the whole board


@dataclass(frozen=True)
class BoardSizeHint:
    """The board size the sampled images suggest.

    Attributes:
        rows, cols: inner corners of the board the images show.
        given_rows, given_cols: inner corners of the target given.
        found: sampled images in which the suggested size was found.
        given_found: sampled images in which the given size was found.
        sampled: images searched.
    """

    rows: int
    cols: int
    given_rows: int
    given_cols: int
    found: int
    given_found: int
    sampled: int

    def message(self, where: str = "the target YAML") -> str:
        """Plain words: what the images show and the keys to change in ``where`` (the target file)."""
        return (
            f"the images look like a checkerboard of {self.rows} x {self.cols} inner corners (rows x cols), not the "
            f"{self.given_rows} x {self.given_cols} given: {self.rows} x {self.cols} was found in {self.found} of "
            f"{self.sampled} sampled images, {self.given_rows} x {self.given_cols} in {self.given_found}; count the "
            f"board's squares and, if it has {self.rows + 1} x {self.cols + 1}, set targetRows: {self.rows} and "
            f"targetCols: {self.cols} in {where}"
        )


def _searchable(image: np.ndarray) -> np.ndarray:
    if image.shape[1] <= MAX_WIDTH:
        return image
    scale = MAX_WIDTH / image.shape[1]
    return cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)


def _board_size(image: np.ndarray, rows: int, cols: int) -> tuple[int, int] | None:
    """Inner corners (rows, cols) of the whole checkerboard in ``image``, turned to match the given
    ``rows`` x ``cols`` as closely as possible; None if no board is found."""
    found, _, meta = cv2.findChessboardCornersSBWithMeta(image, SEED_PATTERN, flags=cv2.CALIB_CB_LARGER)
    if not found or meta is None:
        return None
    a, b = meta.shape[:2]
    return min([(a, b), (b, a)], key=lambda s: abs(s[0] - rows) + abs(s[1] - cols))


def _given_found(images: list[np.ndarray], target: Target) -> int:
    return sum(bool(cv2.findChessboardCorners(im, (target.cols, target.rows), flags=FIND_FLAGS)[0]) for im in images)


def board_size_hint(images: Sequence[np.ndarray], target: Target) -> BoardSizeHint | None:
    """The checkerboard size that ``images`` (a few (H, W) uint8 grey images) show, when not the ``target``'s.

    The size found most often in at least ``MIN_IMAGES`` of the images is suggested when it has more
    corners than the target (a grid cannot show more corners than the board has), or when the
    target's size is found in none of them (a board seen in part shows fewer corners than it has).
    None for aprilgrids (their tags carry their ids), without images, or when the sizes agree.
    """
    if target.kind != "checkerboard" or not len(images):
        return None
    picks = np.unique(np.round(np.linspace(0, len(images) - 1, min(len(images), MAX_SAMPLE))).astype(int))
    sample = [_searchable(images[k]) for k in picks]
    sizes = Counter(s for s in (_board_size(im, target.rows, target.cols) for im in sample) if s is not None)
    given = (target.rows, target.cols)
    candidates = [(n, s[0] * s[1], s) for s, n in sizes.items() if n >= min(MIN_IMAGES, len(sample))]
    if not candidates:
        return None
    found, corners, (rows, cols) = max(candidates)
    if (rows, cols) == given:
        return None
    given_found = _given_found(sample, target)
    if corners <= target.num_points and given_found:
        return None
    return BoardSizeHint(rows, cols, target.rows, target.cols, found, given_found, len(sample))
