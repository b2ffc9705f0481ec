"""A calibration target to print: the board drawn at true scale on a sheet of paper, as a vector PDF and a PNG.

The aprilgrid is Kalibr's (``Target.aprilgrid_image``: tag36h11 tags with their 2-bit black border, black squares
at the tag corners, a white margin of two gaps); the checkerboard has a white border of one square
(``Target.pattern_image``'s default). Both are drawn as black rectangles in millimetres (the PDF holds no raster,
so a printer at 100 % reproduces the sizes of the target YAML), centred on the sheet, with a line that names the
board and the lengths to check with a ruler.

``sheet_layout`` places the board on the paper (turning the sheet to landscape when only that fits) and refuses a
board that does not fit, naming the smallest paper that would hold it.
"""

from __future__ import annotations

import io
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vical.data import Target, TargetError

MM_PER_INCH = 25.4
# ISO 216 and the US sizes [mm], portrait (width, height).
PAPERS = {
    "A4": (210.0, 297.0),
    "A3": (297.0, 420.0),
    "A2": (420.0, 594.0),
    "A1": (594.0, 841.0),
    "A0": (841.0, 1189.0),
    "letter": (215.9, 279.4),
    "legal": (215.9, 355.6),
    "tabloid": (279.4, 431.8),
}
PAGE_MARGIN_MM = 10.0  # what printers leave unprinted at the edges, and room for the label
LABEL_MM = 8.0  # the label's band below the board


@dataclass(frozen=True)
class Sheet:
    """The board on its paper: ``paper`` (W, H) [mm] as printed (landscape when turned), the board's
    ``rectangles`` (N, 4) [mm] x, y (from the top left), width, height, and its ``offset`` on the sheet [mm]."""

    name: str
    paper: tuple[float, float]
    board: tuple[float, float]
    offset: tuple[float, float]
    rectangles: np.ndarray
    label: str


def _runs(black: np.ndarray) -> np.ndarray:
    """(N, 4) pixel rectangles x, y, width, height: each row's runs of black pixels, merged with the rows below that
    repeat them (a tag's black border is a few rectangles, not 100 pixels)."""
    found: list[list[int]] = []
    open_runs: dict[tuple[int, int], int] = {}  # (x, width) -> index in found, for the runs of the previous row
    for y, row in enumerate(black):
        edges = np.flatnonzero(np.diff(np.concatenate([[0], row.astype(np.int8), [0]])))
        runs = {(int(a), int(b - a)) for a, b in zip(edges[::2], edges[1::2], strict=True)}
        still = {}
        for run in sorted(runs):
            if run in open_runs:
                found[open_runs[run]][3] += 1
                still[run] = open_runs[run]
            else:
                found.append([run[0], y, run[1], 1])
                still[run] = len(found) - 1
        open_runs = still
    return np.array(found, dtype=float).reshape(-1, 4)


def _aprilgrid_pixels(target: Target) -> tuple[np.ndarray, float]:
    """The aprilgrid's image at the fewest pixels per tag bit that put its gaps on whole pixels, and its pixel [mm]."""
    for px_per_bit in range(1, 101):
        gap = target.tag_spacing * 10 * px_per_bit
        if abs(gap - round(gap)) < 1e-6 and round(gap) >= 1:
            return target.aprilgrid_image(px_per_bit) < 128, 1e3 * target.row_spacing / (10 * px_per_bit)
    raise TargetError(
        f"tag_spacing {target.tag_spacing} is not a multiple of 1/1000 of the tag size: a printed grid cannot hold it"
    )


def board_rectangles(target: Target) -> tuple[np.ndarray, tuple[float, float]]:
    """The board's black rectangles (N, 4) [mm] x, y, width, height from its top left, and its size (W, H) [mm].

    Aprilgrid: as ``Target.aprilgrid_image`` draws it, x to the right and y up on the print (board frame).
    Checkerboard: square ``(i, j)`` in row ``i`` from the top and column ``j`` from the left, with a white border of
    one square (grid rows along board x, down the sheet, as ``Target.pattern_image``).
    """
    if target.kind == "aprilgrid":
        black, pixel = _aprilgrid_pixels(target)
        return _runs(black) * pixel, (black.shape[1] * pixel, black.shape[0] * pixel)
    row, col = 1e3 * target.row_spacing, 1e3 * target.col_spacing
    i, j = np.meshgrid(np.arange(target.rows + 1), np.arange(target.cols + 1), indexing="ij")
    black = target.square_is_black(i, j)
    rects = np.column_stack([(j[black] + 1) * col, (i[black] + 1) * row, np.full(black.sum(), col),
                             np.full(black.sum(), row)])  # fmt: skip
    return rects, ((target.cols + 3) * col, (target.rows + 3) * row)


def check_lengths(target: Target) -> str:
    """What to measure on the print: the tag's side (or a square's) and the board's extent of tags or squares."""
    if target.kind == "aprilgrid":
        size = 1e3 * target.row_spacing
        gap = size * target.tag_spacing
        width = target.cols * size + (target.cols - 1) * gap
        return f"a tag's black side is {size:.1f} mm and the {target.cols} tags of a row span {width:.1f} mm"
    row, col = 1e3 * target.row_spacing, 1e3 * target.col_spacing
    return (f"a square is {col:.1f} x {row:.1f} mm and the {target.cols + 1} squares of a row span "
            f"{(target.cols + 1) * col:.1f} mm")  # fmt: skip


def describe(target: Target) -> str:
    if target.kind == "aprilgrid":
        return (f"aprilgrid {target.rows} x {target.cols} tags (tag36h11, ids 0-{target.num_tags - 1}), tag "
                f"{1e3 * target.row_spacing:g} mm, spacing {target.tag_spacing:g}")  # fmt: skip
    return (f"checkerboard {target.rows} x {target.cols} inner corners, squares {1e3 * target.col_spacing:g} x "
            f"{1e3 * target.row_spacing:g} mm")  # fmt: skip


def _fits(board: tuple[float, float], paper: tuple[float, float]) -> bool:
    return board[0] + 2 * PAGE_MARGIN_MM <= paper[0] and board[1] + 2 * PAGE_MARGIN_MM + LABEL_MM <= paper[1]


def sheet_layout(target: Target, paper: str) -> Sheet:
    """The board centred on ``paper`` (portrait, or landscape when only that fits); ``TargetError`` naming the
    smallest paper that holds it when it does not fit."""
    if paper not in PAPERS:
        raise TargetError(f"paper {paper!r} is not one of {', '.join(PAPERS)}")
    rects, board = board_rectangles(target)
    portrait = PAPERS[paper]
    for size in (portrait, portrait[::-1]):
        if _fits(board, size):
            offset = ((size[0] - board[0]) / 2, (size[1] - board[1] - LABEL_MM) / 2)
            label = f"vical target: {describe(target)}. Print at 100 %; check with a ruler: {check_lengths(target)}."
            return Sheet(paper, size, board, offset, rects, label)
    holds = [name for name, size in PAPERS.items() if _fits(board, size) or _fits(board, size[::-1])]
    bigger = f"--paper {holds[0]} holds it" if holds else f"no paper here holds it ({', '.join(PAPERS)})"
    raise TargetError(
        f"the {describe(target)} is {board[0]:.0f} x {board[1]:.0f} mm with its white margin; {paper} is "
        f"{portrait[0]:g} x {portrait[1]:g} mm ({PAGE_MARGIN_MM:g} mm kept free at its edges): {bigger}, or choose "
        "smaller tags or squares"
    )


def _figure(sheet: Sheet):
    from matplotlib.collections import PolyCollection  # here: only printing a target pays matplotlib's import
    from matplotlib.figure import Figure

    width, height = sheet.paper
    figure = Figure(figsize=(width / MM_PER_INCH, height / MM_PER_INCH))
    axes = figure.add_axes((0.0, 0.0, 1.0, 1.0))
    axes.set_xlim(0.0, width)
    axes.set_ylim(height, 0.0)  # millimetres from the sheet's top left
    axes.set_axis_off()
    x, y, w, h = (sheet.rectangles + [sheet.offset[0], sheet.offset[1], 0.0, 0.0]).T
    corners = np.stack([np.column_stack(c) for c in ((x, y), (x + w, y), (x + w, y + h), (x, y + h))], axis=1)
    axes.add_collection(PolyCollection(corners, facecolors="black", edgecolors="none", antialiaseds=False))
    label_y = sheet.offset[1] + sheet.board[1] + LABEL_MM / 2
    axes.text(width / 2, label_y, sheet.label, ha="center", va="center", fontsize=6, wrap=True)
    return figure


def write_sheet(sheet: Sheet, pdf: str | os.PathLike, png: str | os.PathLike, dpi: int = 300) -> None:
    """The sheet as a PDF (vector, at true size) and as a PNG of ``dpi`` (its resolution recorded in the file).

    Each is drawn in memory, then written: matplotlib's PDF writer, meeting a full disk, raises a second error
    while it closes the file, where Python's own write raises the ``OSError`` (ENOSPC) that the command reports."""
    figure = _figure(sheet)
    for path, kind, options in ((pdf, "pdf", {}), (png, "png", {"dpi": dpi})):
        drawn = io.BytesIO()
        figure.savefig(drawn, format=kind, **options)
        Path(path).write_bytes(drawn.getbuffer())
