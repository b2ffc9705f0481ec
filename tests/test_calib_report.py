"""Results text, plots and weak-parameter hints of real calibrations."""

import numpy as np

from vical.calib.intrinsics import calibrate_intrinsics
from vical.calib.report import results_text, summary_table, write_report
from vical.calib.synthetic import Excitation, make_recording

SIZE = (640, 480)


def test_far_head_on_views_flag_focal_length_with_a_hint():
    weak = Excitation(distance=1.6).scaled(rotation=0.15, translation=0.3)
    rec = make_recording(duration=6.0, excitation=weak, pixel_sigma=0.3, seed=4)
    result = calibrate_intrinsics(rec.frames, rec.target, "radtan", SIZE)
    names = [w.name for w in result.weak_parameters]
    assert "fx" in names and "cx" in names
    fx = next(w for w in result.weak_parameters if w.name == "fx")
    assert "closer" in fx.hint and fx.sigma > fx.threshold
    assert np.abs(result.camera.fx - rec.truth.camera.fx) < 4 * fx.sigma


def test_well_excited_views_flag_no_intrinsic_but_report_the_numbers(tmp_path):
    rec = make_recording(duration=10.0, pixel_sigma=0.3, seed=8)
    result = calibrate_intrinsics(rec.frames, rec.target, "radtan", SIZE)
    assert not [w for w in result.weak_parameters if w.name in ("fx", "fy", "cx", "cy")]
    text = results_text(result)
    assert f"{result.camera.fx:.6f}" in text and f"+- {result.sigma('fx'):.4g} px" in text
    assert "reprojection" in summary_table(result)
    written = write_report(tmp_path, result)
    assert [p.name for p in written] == ["reprojection.png", "report.pdf"]
    assert not list(tmp_path.glob(".*tmp*"))  # atomic writes leave no temporaries
