"""Calibration target geometry (the board's 3D points in the board frame).

Point numbering follows Kalibr so that observations exchange with Kalibr tools unchanged:
for a checkerboard with ``rows x cols`` inner corners the point of grid row ``r`` and column
``c`` has id ``r * cols + c`` and board-frame position ``(r * row_spacing, c * col_spacing, 0)``
[m]; the board frame's z axis is ``x cross y``. Seen with grid rows going down the image and
columns going right, z points out of the printed side towards the camera. ``cv2.findChessboardCorners`` with
``patternSize = (cols, rows)`` returns corners in this id order (up to the pattern's 180 deg
symmetry, which the detector resolves with the colour convention below).

Checkerboard colours: the square diagonally outside point id 0 (board coordinates x < 0, y < 0)
is black, and colours alternate from there (``Target.square_is_black``). A board with an odd
number of squares along one side and an even number along the other (the paper's 8 x 7) is not
symmetric under a half-turn, so this fixes which corner is id 0.

Aprilgrid (Kalibr's ``GridCalibrationTargetAprilgrid``): ``rows x cols`` AprilTags (tag36h11) of
side ``tag_size`` [m] (the outer edge of the tag's 2-bit black border) separated by gaps of
``tag_spacing * tag_size``. Its points are the four corners of every tag, on a grid of
``2 rows x 2 cols`` points: point ``(r, c)`` (id ``r * 2 cols + c``) lies at
``x = (c // 2) (1 + tag_spacing) tag_size + (c % 2) tag_size``,
``y = (r // 2) (1 + tag_spacing) tag_size + (r % 2) tag_size``, z = 0. Unlike the checkerboard,
x runs along the grid columns and y along the rows (Kalibr's choice). Tag ``k`` sits in tag row
``k // cols`` and tag column ``k % cols``; its corners, counter-clockwise from (min x, min y), are
the point ids ``b, b + 1, b + 2 cols + 1, b + 2 cols`` with ``b = (k // cols) 4 cols + (k % cols) 2``.
The printed grid is seen from +z: x to the right and y up on the print.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

# Tag 0 of tag36h11 as Kalibr lists it (kalibr_create_target_pdf, from the AprilTags C++ library).
# Kalibr prints bit ``35 - (6 i + j)`` of the code in data row ``i`` (from the top) and column ``j``
# (from the left), white where the bit is set. OpenCV's marker images are this print turned by a
# multiple of 90 deg that depends on the OpenCV version (OpenCV 5.0.0 draws it upside down), so
# ``aprilgrid_image`` measures the turn on this one code and undoes it.
KALIBR_TAG36H11_ID0 = 0xD5D628584


def kalibr_tag_bits(code: int) -> np.ndarray:
    """(6, 6) bool data bits of a tag36h11 code as Kalibr prints it, True = black, row 0 at the top."""
    index = 35 - (6 * np.arange(6)[:, None] + np.arange(6)[None, :])
    return (code >> index) & 1 == 0


@functools.cache
def opencv_tag_turns() -> int:
    """Quarter turns ``k`` with ``np.rot90(opencv_marker, k)`` = Kalibr's print of the same tag36h11 id."""
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    marker = cv2.aruco.generateImageMarker(dictionary, 0, 100, borderBits=2)
    bits = marker[25:80:10, 25:80:10] < 128  # centres of the 6 x 6 data cells (10 px each, 2-cell border)
    for k in range(4):
        if np.array_equal(np.rot90(bits, k), kalibr_tag_bits(KALIBR_TAG36H11_ID0)):
            return k
    raise TargetError("OpenCV's DICT_APRILTAG_36h11 tag 0 matches Kalibr's tag 0 in no orientation")


class TargetError(ValueError):
    """Target parameters that cannot describe a board."""


@dataclass(frozen=True)
class Target:
    """A planar calibration target.

    Attributes:
        kind: ``"checkerboard"`` or ``"aprilgrid"``.
        rows, cols: checkerboard: inner corners; aprilgrid: tags (Kalibr's ``tagRows``, ``tagCols``).
        row_spacing, col_spacing: checkerboard: distance between neighbouring points [m];
            aprilgrid: both the tag size [m] (Kalibr's ``tagSize``).
        tag_spacing: aprilgrid only: gap between tags / tag size (Kalibr's ``tagSpacing``).
    """

    kind: str
    rows: int
    cols: int
    row_spacing: float
    col_spacing: float
    tag_spacing: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in ("checkerboard", "aprilgrid"):
            raise TargetError(f"target kind {self.kind!r} unknown; use 'checkerboard' or 'aprilgrid'")
        if self.rows < 2 or self.cols < 2:
            raise TargetError(f"target needs at least 2 x 2 points, got rows={self.rows}, cols={self.cols}")
        if not (self.row_spacing > 0 and self.col_spacing > 0):
            raise TargetError(
                f"target spacing must be positive [m], got row_spacing={self.row_spacing}, "
                f"col_spacing={self.col_spacing}"
            )
        if self.kind == "aprilgrid" and (self.row_spacing != self.col_spacing or not self.tag_spacing > 0):
            raise TargetError(
                f"an aprilgrid needs one tag size (row_spacing == col_spacing) and tag_spacing > 0, got "
                f"{self.row_spacing}, {self.col_spacing}, tag_spacing={self.tag_spacing}"
            )

    @classmethod
    def checkerboard(cls, rows: int = 6, cols: int = 7, square: float = 0.07) -> Target:
        """Checkerboard with ``rows x cols`` inner corners and square side ``square`` [m].

        The default is the paper's board: 8 x 7 squares of 7 cm = 7 x 6 inner corners.
        """
        return cls("checkerboard", int(rows), int(cols), float(square), float(square))

    @classmethod
    def aprilgrid(
        cls, tag_rows: int = 6, tag_cols: int = 6, tag_size: float = 0.088, tag_spacing: float = 0.3
    ) -> Target:
        """Kalibr aprilgrid of ``tag_rows x tag_cols`` tag36h11 tags of side ``tag_size`` [m].

        The default is Kalibr's ``april_6x6.yaml`` (88 mm tags, gaps of 0.3 tag sizes).
        """
        return cls("aprilgrid", int(tag_rows), int(tag_cols), float(tag_size), float(tag_size), float(tag_spacing))

    @property
    def grid_shape(self) -> tuple[int, int]:
        """(rows, cols) of the point grid: the inner corners, or 2 x the tags of an aprilgrid."""
        return (2 * self.rows, 2 * self.cols) if self.kind == "aprilgrid" else (self.rows, self.cols)

    @property
    def num_points(self) -> int:
        rows, cols = self.grid_shape
        return rows * cols

    @property
    def num_tags(self) -> int:
        """Number of AprilTags (ids 0 .. num_tags - 1) of an aprilgrid; 0 for a checkerboard."""
        return self.rows * self.cols if self.kind == "aprilgrid" else 0

    @functools.cached_property
    def points(self) -> np.ndarray:
        """(N, 3) [m] board-frame points, row ``i`` is point id ``i`` (read-only: computed once per target, it is
        read for every simulated and detected frame)."""
        if self.kind == "aprilgrid":
            points = self._aprilgrid_points()
        else:
            r, c = np.divmod(np.arange(self.num_points), self.cols)
            points = np.stack([r * self.row_spacing, c * self.col_spacing, np.zeros(self.num_points)], axis=1)
        points.flags.writeable = False
        return points

    def _aprilgrid_points(self) -> np.ndarray:
        r, c = np.divmod(np.arange(self.num_points), 2 * self.cols)
        pitch = (1.0 + self.tag_spacing) * self.row_spacing
        x = (c // 2) * pitch + (c % 2) * self.row_spacing
        y = (r // 2) * pitch + (r % 2) * self.row_spacing
        return np.stack([x, y, np.zeros(self.num_points)], axis=1)

    def tag_corner_ids(self, tag_ids: np.ndarray) -> np.ndarray:
        """(T, 4) point ids of the corners of aprilgrid tags ``tag_ids`` (T,), counter-clockwise
        from the corner at (min x, min y) as Kalibr orders them."""
        if self.kind != "aprilgrid":
            raise TargetError(f"a {self.kind} has no tags")
        tag_ids = np.asarray(tag_ids, dtype=np.int64).reshape(-1)
        if np.any((tag_ids < 0) | (tag_ids >= self.num_tags)):
            raise TargetError(f"tag ids must be in 0..{self.num_tags - 1}, got {tag_ids.tolist()}")
        grid_cols = 2 * self.cols
        base = (tag_ids // self.cols) * 2 * grid_cols + (tag_ids % self.cols) * 2
        return np.stack([base, base + 1, base + grid_cols + 1, base + grid_cols], axis=1)

    @property
    def center(self) -> np.ndarray:
        """(3,) [m] centre of the point grid in the board frame."""
        if self.kind == "aprilgrid":
            p = self.points
            return (p.min(axis=0) + p.max(axis=0)) / 2.0
        return np.array([(self.rows - 1) * self.row_spacing / 2.0, (self.cols - 1) * self.col_spacing / 2.0, 0.0])

    @property
    def outline(self) -> np.ndarray:
        """(4, 3) [m] the grid's outer points (ids 0, C-1, N-1, N-C with C grid columns), in order around the grid."""
        n, c = self.num_points, self.grid_shape[1]
        return self.points[[0, c - 1, n - 1, n - c]]

    def square_is_black(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Colour of checkerboard square ``(i, j)``, ``i`` in [0, rows], ``j`` in [0, cols].

        Square ``(i, j)`` spans x in [(i - 1) row_spacing, i row_spacing] and y in
        [(j - 1) col_spacing, j col_spacing]; square (0, 0) is black.
        """
        return (np.asarray(i) + np.asarray(j)) % 2 == 0

    def pattern_image(self, px_per_square: int = 100, border_squares: float = 1.0) -> np.ndarray:
        """Grey image (uint8) of the printed checkerboard with a white border.

        Image row index grows with board x (grid rows), column index with board y (grid
        columns); pixel ``(a, b)``'s centre lies at board coordinates
        ``x = (a + 0.5) / px_per_square * row_spacing - (1 + border_squares) * row_spacing``
        (likewise y with ``b`` and ``col_spacing``). ``border_squares`` of white surround the
        ``(rows + 1) x (cols + 1)`` squares.
        """
        if self.kind != "checkerboard":
            raise TargetError(f"pattern_image draws checkerboards only, not {self.kind!r}")
        border = round(border_squares * px_per_square)
        a = np.arange((self.rows + 1) * px_per_square)
        b = np.arange((self.cols + 1) * px_per_square)
        black = self.square_is_black(a[:, None] // px_per_square, b[None, :] // px_per_square)
        squares = np.where(black, 0, 255).astype(np.uint8)
        return np.pad(squares, border, constant_values=255)

    def aprilgrid_image(self, px_per_bit: int = 10) -> np.ndarray:
        """Grey image (uint8) of the printed aprilgrid, as Kalibr prints it.

        Each tag is a tag36h11 code (OpenCV's ``DICT_APRILTAG_36h11``, turned to Kalibr's print
        orientation: ``opencv_tag_turns``) with a 2-bit black border: ``10 px_per_bit`` px per
        ``tag_size``. Black squares of the gap's size sit at every tag
        corner (between tags and around the grid), and a white border of one gap surrounds it.
        With ``g`` the gap [px] and ``m = 2 g`` the margin, pixel ``(a, b)`` (row, column) of the
        ``H``-row image has its centre at board ``x = (b + 0.5 - m) s``, ``y = (H - a - 0.5 - m) s``
        with ``s = tag_size / (10 px_per_bit)`` [m/px]: x to the right, y up, as printed.
        """
        if self.kind != "aprilgrid":
            raise TargetError(f"aprilgrid_image draws aprilgrids only, not {self.kind!r}")
        tag_px = 10 * int(px_per_bit)
        gap_px = round(self.tag_spacing * tag_px)
        if abs(gap_px - self.tag_spacing * tag_px) > 1e-6 or gap_px < 1:
            raise TargetError(
                f"tag_spacing {self.tag_spacing} x {tag_px} px is not a whole number of pixels; "
                "choose px_per_bit so that it is"
            )
        pitch, margin = tag_px + gap_px, 2 * gap_px
        height = 2 * margin + self.rows * pitch - gap_px
        width = 2 * margin + self.cols * pitch - gap_px
        image = np.full((height, width), 255, dtype=np.uint8)
        dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
        turns = opencv_tag_turns()
        for k in range(self.num_tags):
            top = height - margin - (k // self.cols) * pitch - tag_px
            left = margin + (k % self.cols) * pitch
            marker = cv2.aruco.generateImageMarker(dictionary, k, tag_px, borderBits=2)
            image[top : top + tag_px, left : left + tag_px] = np.rot90(marker, turns)
        for i in range(self.rows + 1):
            for j in range(self.cols + 1):
                top, left = height - margin - i * pitch, margin + j * pitch - gap_px
                image[top : top + gap_px, left : left + gap_px] = 0
        return image

    def to_dict(self) -> dict:
        return {
            "kind": self.kind,
            "rows": self.rows,
            "cols": self.cols,
            "row_spacing": self.row_spacing,
            "col_spacing": self.col_spacing,
            "tag_spacing": self.tag_spacing,
        }

    @classmethod
    def from_dict(cls, d: dict) -> Target:
        return cls(
            kind=d["kind"],
            rows=int(d["rows"]),
            cols=int(d["cols"]),
            row_spacing=float(d["row_spacing"]),
            col_spacing=float(d["col_spacing"]),
            tag_spacing=float(d.get("tag_spacing", 0.0)),
        )
