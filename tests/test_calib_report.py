"""Results text, plots and weak-parameter hints of real calibrations."""

import re
import zlib

import numpy as np
import pytest

from vical.calib.metrics import calibration_errors
from vical.calib.report import figures
from vical.calib.report.writers import results_text, summary_table, write_report
from vical.calib.solve.intrinsics import calibrate_intrinsics
from vical.calib.solve.pipeline import calibrate_joint
from vical.calib.synthetic import Excitation, make_recording
from vical.data import ImuNoise

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


def pdf_pages_and_text(path) -> tuple[int, str]:
    """Page count and the text shown on the pages of a PDF written by matplotlib (its TJ operators; "ff" is
    one glyph there, so words with it are not searchable)."""
    data = path.read_bytes()
    pages = len(re.findall(rb"/Type\s*/Page\b", data))
    shown = []
    for stream in re.findall(rb"stream\n(.*?)endstream", data, re.S):
        try:
            content = zlib.decompress(stream)
        except zlib.error:  # fonts and images
            continue
        for array in re.findall(rb"\[(.*?)\]\s*TJ", content, re.S):
            pieces = re.findall(rb"\(((?:\\.|[^\\)])*)\)", array)
            shown.append(re.sub(rb"\\(.)", rb"\1", b"".join(pieces)).decode("latin-1"))
    return pages, "\n".join(shown)


GYRO_BIAS, ACCEL_BIAS = np.array([0.01, -0.02, 0.015]), np.array([0.1, -0.05, 0.08])  # [rad/s], [m/s^2]


@pytest.fixture(scope="module")
def joint():
    rec = make_recording(duration=8.0, time_offset=0.012, imu_noise=ImuNoise(), pixel_sigma=0.3, seed=21,
                         gyro_bias=GYRO_BIAS, accel_bias=ACCEL_BIAS)  # fmt: skip
    return rec, calibrate_joint(rec.frames, rec.imu, rec.target, "radtan", SIZE, rec.truth.imu_noise)


def test_the_pdf_report_has_a_page_per_topic_with_the_parameters_first(joint, tmp_path):
    rec, result = joint
    errors = calibration_errors(result, rec.truth)
    write_report(tmp_path, result, errors)
    pages, text = pdf_pages_and_text(tmp_path / "report.pdf")
    titles = ["vical calibration report: joint", "Reprojection residuals", "Coverage: where the board's corners",
              "Frames: detected, used and not used", "IMU: mean rates per state interval", "IMU residuals: measured",
              "IMU biases over time", "IMU sample spacing",
              "the camera's rotation rate (in the IMU frame) against the gyro", "Notes"]  # fmt: skip
    assert pages == len(titles) == 10
    positions = [text.index(title) for title in titles]
    assert positions == sorted(positions)  # in this order
    first_page = " ".join(text[: positions[1]].split())  # spaces squashed
    assert f"fx {result.camera.fx:.6f} +- {result.sigma('fx'):.4g} px" in first_page
    assert f"time offset {errors.time_offset_ms:.4f} ms" in first_page and "errors against the truth" in first_page
    assert "frames: 79 frames, the board detected in 66, 66 used" in first_page
    assert "warnings:" in text[positions[-1] :]


def test_an_intrinsic_report_leaves_out_the_imu_pages(tmp_path):
    rec = make_recording(duration=6.0, pixel_sigma=0.3, seed=8)
    result = calibrate_intrinsics(rec.frames, rec.target, "radtan", SIZE)
    write_report(tmp_path, result)
    pages, text = pdf_pages_and_text(tmp_path / "report.pdf")
    assert pages == 5 and "IMU" not in text and "rotation rate" not in text


def test_the_time_offset_page_shows_the_camera_rates_matching_the_gyro_at_the_offset(joint):
    _, result = joint
    trace = result.time_offset_trace
    best = trace.shifts[np.nanargmin(trace.mismatch)]
    step = trace.shifts[1] - trace.shifts[0]
    assert abs(best - result.time_offset) <= step / 2 and abs(best - 0.012) < 1e-3
    assert np.nanmax(trace.mismatch) > 2 * np.nanmin(trace.mismatch)  # a clear minimum over +-50 ms
    # The camera's mean rate over each frame pair against the gyro at the pair's middle, shifted by the offset.
    gyro = np.column_stack(
        [np.interp(trace.t_camera + result.time_offset, trace.t_imu, trace.gyro[:, i]) for i in range(3)]
    )
    rms_rate = np.sqrt(np.mean(np.sum(gyro**2, axis=1)))
    rms_difference = np.sqrt(np.mean(np.sum((trace.omega_camera - gyro) ** 2, axis=1)))
    assert rms_rate > 0.5 and rms_difference < 0.05 * rms_rate


def test_the_bias_page_shows_each_states_biases_around_the_truth_within_the_declared_walk(joint):
    rec, result = joint
    imu, noise = result.imu_residuals, rec.truth.imu_noise
    page = figures.imu_bias_page(result)
    since = imu.t - imu.t[0]
    sensors = [(imu.gyro_bias, GYRO_BIAS, noise.gyro_random_walk, "bg"),
               (imu.accel_bias, ACCEL_BIAS, noise.accel_random_walk, "ba")]  # fmt: skip
    for k, ax in enumerate(page.axes):  # rows x, y, z; columns gyro, accel
        (estimate, truth, walk, name), i = sensors[k % 2], k // 2
        line, upper, lower = (line.get_ydata() for line in ax.lines[:3])
        np.testing.assert_array_equal(line, estimate[:, i])
        np.testing.assert_allclose(upper - estimate[0, i], 3 * walk * np.sqrt(since), rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(lower - estimate[0, i], -3 * walk * np.sqrt(since), rtol=1e-9, atol=1e-15)
        # the truth recovered at every state: within 3 sigma of the first state's estimate and the walk since
        sigma = result.sigma(f"{name}_{'xyz'[i]}")
        assert np.all(np.abs(line - truth[i]) <= 3 * sigma + 3 * walk * np.sqrt(since)), (name, i)
    assert imu.gyro_bias[0] == pytest.approx(result.gyro_bias, abs=1e-12)
    assert imu.accel_bias[0] == pytest.approx(result.accel_bias, abs=1e-12)


def _spacing_title(t: np.ndarray) -> str:
    return figures.imu_spacing_page(t)._suptitle.get_text()


def test_the_spacing_page_shows_the_solves_imu_samples_a_dropped_run_and_jitter(joint):
    rec, result = joint
    t = result.time_offset_trace.t_imu
    np.testing.assert_allclose(np.diff(t), np.diff(rec.imu.t) / 1e9, atol=1e-9)  # the recording's samples, each
    title = _spacing_title(t)
    assert f"{len(t)} samples at 200 Hz (the median), jitter 0.0 us, gaps over 1.5 x the median: 0," in title, title
    assert title.endswith("the longest spacing 5 ms"), title
    title = _spacing_title(np.delete(t, np.arange(500, 520)))  # 20 samples lost: one gap of 21 periods
    assert f"{len(t) - 20} samples at 200 Hz (the median), jitter 0.0 us, gaps over 1.5 x the median: 1," in title
    assert title.endswith("the longest spacing 105 ms"), title
    # stamps with white jitter of 100 us: their spacing spreads by sqrt(2) x 100 us
    jittered = t + np.random.default_rng(0).normal(0.0, 100e-6, len(t))
    jitter = float(re.search(r"jitter ([\d.]+) us", _spacing_title(jittered)).group(1))
    assert jitter == pytest.approx(np.sqrt(2) * 100, rel=0.1)


def test_weak_parameters_are_named_in_the_units_of_the_first_page_and_the_plots_are_labelled(tmp_path):
    little_rotation = Excitation().scaled(rotation=0.3)
    rec = make_recording(duration=6.0, excitation=little_rotation, imu_noise=ImuNoise(), pixel_sigma=0.3, seed=4)
    result = calibrate_joint(rec.frames, rec.imu, rec.target, "radtan", SIZE, rec.truth.imu_noise)
    weak = {w.name: w for w in result.weak_parameters}
    assert {"t_x", "rot_z", "fx", "k2"} <= set(weak)  # measured 4.0 mm, 0.16 deg, 1.8 px, 0.015
    write_report(tmp_path, result)
    _, text = pdf_pages_and_text(tmp_path / "report.pdf")
    notes = " ".join(text[text.index("Notes") :].split())
    first_page = " ".join(text[: text.index("Reprojection residuals")].split())
    t_x = weak["t_x"].sigma * 1e3
    assert f"+- {t_x:.4g} mm" in first_page and f"t_x: 1-sigma {t_x:.3g} mm > 2 mm ->" in notes
    assert f"fx: 1-sigma {weak['fx'].sigma:.3g} px > {weak['fx'].threshold:.3g} px ->" in notes
    assert f"rot_z: 1-sigma {np.rad2deg(weak['rot_z'].sigma):.3g} deg > 0.1 deg ->" in notes
    assert f"k2: 1-sigma {weak['k2'].sigma:.3g} > 0.01 ->" in notes  # a distortion coefficient has no unit
    arrows = figures.reprojection_page(result)
    assert "|residual| [px] (arrow colour)" in [ax.get_ylabel() for ax in arrows.axes]  # the arrows' colour bar
    counts = figures.frames_page(result.frame_log).axes[0]
    assert counts.get_ylim()[0] == 0.0
