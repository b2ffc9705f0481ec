"""vical-target: the printed board's geometry is the YAML's (the PDF rasterised at 300 dpi and detected by vical's
own detectors), the PNG is the same sheet, and a board that cannot be printed is one line with nothing written."""

from pathlib import Path

import numpy as np
import pypdfium2
import pytest
from matplotlib import image as mpimg

from vical.apps.target import main
from vical.calib.detection.aprilgrid import detect_aprilgrid
from vical.calib.detection.checkerboard import detect_checkerboard
from vical.data import Target
from vical.io.kalibr import read_target_yaml
from vical.io.printable_target import _runs

DPI = 300
PX_PER_MM = DPI / 25.4

BOARDS = {
    "aprilgrid": (["--rows", "4", "--cols", "5", "--size", "0.03", "--spacing", "0.25", "--paper", "A4"],
                  Target("aprilgrid", 4, 5, 0.03, 0.03, 0.25)),
    "checkerboard": (["--kind", "checkerboard", "--rows", "7", "--cols", "6", "--size", "0.02", "--paper", "A4"],
                     Target("checkerboard", 7, 6, 0.02, 0.02)),
}  # fmt: skip


def rasterised(pdf: Path) -> np.ndarray:
    """The PDF's first page at 300 dpi, grey, as a printer's driver renders it."""
    bitmap = pypdfium2.PdfDocument(pdf)[0].render(scale=DPI / 72, grayscale=True).to_numpy()
    return np.ascontiguousarray(bitmap[..., 0] if bitmap.ndim == 3 else bitmap)


def scale_and_residual(image: np.ndarray, target: Target) -> tuple[float, float, int]:
    """The detected corners against the board's points [mm]: the affine map's scale [px/mm], its largest residual
    [px] and the number of corners."""
    detect = detect_aprilgrid if target.kind == "aprilgrid" else detect_checkerboard
    corners, ids = detect(image, target)
    points = np.column_stack([1e3 * target.points[ids][:, :2], np.ones(len(ids))])
    affine, *_ = np.linalg.lstsq(points, corners, rcond=None)
    return float(np.sqrt(abs(np.linalg.det(affine[:2])))), float(np.abs(corners - points @ affine).max()), len(ids)


@pytest.mark.parametrize("kind", sorted(BOARDS))
def test_the_printed_board_has_the_yamls_geometry_within_a_thousandth(kind, tmp_path, capsys):
    args, target = BOARDS[kind]
    assert main(["--out", str(tmp_path / "board"), *args]) == 0
    assert read_target_yaml(tmp_path / "board" / "target.yaml") == target
    printed = capsys.readouterr().out
    assert "print at 100 %" in printed and "check with a ruler:" in printed
    every = target.num_tags * 4 if kind == "aprilgrid" else target.rows * target.cols
    png = (255 * mpimg.imread(tmp_path / "board" / "target.png")[..., 0]).round().astype(np.uint8)
    for image in (rasterised(tmp_path / "board" / "target.pdf"), png):
        scale, residual, found = scale_and_residual(image, target)
        assert found == every and abs(scale / PX_PER_MM - 1) < 1e-3 and residual < 1.0, (scale, residual, found)


def test_the_sheet_is_the_paper_and_turns_to_landscape_only_when_the_board_needs_it(tmp_path):
    assert main(["--out", str(tmp_path / "a"), *BOARDS["aprilgrid"][0]]) == 0  # 210 x 172.5 mm + label: landscape
    assert main(["--out", str(tmp_path / "c"), *BOARDS["checkerboard"][0]]) == 0  # 180 x 200 mm: portrait
    for name, size_mm in (("a", (297, 210)), ("c", (210, 297))):
        width_pt, height_pt = pypdfium2.PdfDocument(tmp_path / name / "target.pdf")[0].get_size()
        assert np.allclose([width_pt, height_pt], np.array(size_mm) * 72 / 25.4, atol=0.01)


def test_the_rectangles_are_the_boards_black_pixels_exactly():
    black = Target("aprilgrid", 3, 4, 0.05, 0.05, 0.3).aprilgrid_image(1) < 128
    painted = np.zeros_like(black)
    for x, y, w, h in _runs(black).astype(int):
        assert not painted[y : y + h, x : x + w].any()  # no pixel twice
        painted[y : y + h, x : x + w] = True
    assert np.array_equal(painted, black)


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (["--size", "0.088", "--paper", "A4"],
         "vical-target: error: the aprilgrid 6 x 6 tags (tag36h11, ids 0-35), tag 88 mm, spacing 0.3 is 766 x 766 mm "
         "with its white margin; A4 is 210 x 297 mm (10 mm kept free at its edges): --paper A0 holds it, or choose "
         "smaller tags or squares"),
        ([], "vical-target: error: give the board with --size [m] (its tag's or square's side) or --target <Kalibr "
             "target YAML>"),
        (["--size", "0.02", "--dpi", "5000"], "vical-target: error: --dpi 5000: give a resolution from 30 to 1200"),
        (["--size", "-0.02"], "vical-target: error: target spacing must be positive [m], got row_spacing=-0.02, "
                              "col_spacing=-0.02"),
        (["--size", "0.02", "--paper", "B5"], "vical-target: error: argument --paper: invalid choice: 'B5'"),
    ],
    ids=["too big for the paper", "no size", "absurd dpi", "negative size", "unknown paper"],
)  # fmt: skip
def test_a_board_that_cannot_be_printed_is_one_line_and_nothing_is_written(args, line, tmp_path, capsys):
    assert main(["--out", str(tmp_path / "board"), *args]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(line) and "\n" not in err, err
    assert not (tmp_path / "board").exists()


def test_an_out_holding_a_target_is_replaced_only_with_overwrite(tmp_path, capsys):
    out = tmp_path / "board"
    args = ["--out", str(out), "--size", "0.02", "--rows", "3", "--cols", "3"]
    assert main(args) == 0
    before = (out / "target.yaml").read_text()
    assert main([*args[:3], "0.025", *args[4:]]) == 2
    assert "holds target.pdf, target.png, target.yaml; choose another directory or pass --overwrite" in (
        capsys.readouterr().err
    )
    assert (out / "target.yaml").read_text() == before
    assert main([*args[:3], "0.025", *args[4:], "--overwrite"]) == 0
    assert read_target_yaml(out / "target.yaml").row_spacing == 0.025
