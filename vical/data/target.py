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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


class TargetError(ValueError):
    """Target parameters that cannot describe a board."""


@dataclass(frozen=True)
class Target:
    """A planar calibration target.

    Attributes:
        kind: ``"checkerboard"`` (``"aprilgrid"`` reserved for the aprilgrid target).
        rows, cols: grid size (checkerboard: inner corners).
        row_spacing, col_spacing: distance between neighbouring points [m].
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

    @classmethod
    def checkerboard(cls, rows: int = 6, cols: int = 7, square: float = 0.07) -> Target:
        """Checkerboard with ``rows x cols`` inner corners and square side ``square`` [m].

        The default is the paper's board: 8 x 7 squares of 7 cm = 7 x 6 inner corners.
        """
        return cls("checkerboard", int(rows), int(cols), float(square), float(square))

    @property
    def num_points(self) -> int:
        return self.rows * self.cols

    @property
    def points(self) -> np.ndarray:
        """(N, 3) [m] board-frame points, row ``i`` is point id ``i``."""
        r, c = np.divmod(np.arange(self.num_points), self.cols)
        return np.stack([r * self.row_spacing, c * self.col_spacing, np.zeros(self.num_points)], axis=1)

    @property
    def center(self) -> np.ndarray:
        """(3,) [m] centre of the point grid in the board frame."""
        return np.array([(self.rows - 1) * self.row_spacing / 2.0, (self.cols - 1) * self.col_spacing / 2.0, 0.0])

    @property
    def outline(self) -> np.ndarray:
        """(4, 3) [m] the grid's outer points (ids 0, cols-1, N-1, N-cols), in order around the grid."""
        n, c = self.num_points, self.cols
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
