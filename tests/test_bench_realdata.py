"""experiments/bench_realdata.py on 10 s of the real dev set: vical and its peers run, and agree with the references."""

import re
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))
import bench_realdata  # noqa: E402

needs_realdata = pytest.mark.skipif(
    not bench_realdata.DATA.is_dir(),
    reason=f"the real dev set is not at {bench_realdata.DATA} (it lies beside the repo)",
)


@needs_realdata
def test_ten_real_seconds_calibrate_near_both_published_extrinsics_beside_the_peers(tmp_path, capsys):
    assert bench_realdata.main(["--quick", "--out", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    row = next(line for line in text.splitlines() if line.startswith("cam0      extrinsic"))
    fields = row.split()
    euroc_deg, euroc_mm, basalt_deg, basalt_mm = map(float, fields[4:8])
    # 10 s of hand-held motion: looser than the 30 s acceptance (0.25 deg / 10 mm of EuRoC's, 0.5 deg of Basalt's)
    assert euroc_deg < 0.3 and euroc_mm < 15 and basalt_deg < 0.5 and basalt_mm < 15
    assert abs(float(fields[8])) < 0.5  # [ms] hardware-synchronised
    plain = re.search(r"plain GTSAM cam0 0-10 s: EuRoC ([\d.]+) deg ([\d.]+) mm", text)
    assert plain and float(plain.group(1)) < 0.5 and float(plain.group(2)) < 20
    opencv = re.search(r"OpenCV calibrateCamera cam0 0-10 s: fx ([+-][\d.]+) % fy ([+-][\d.]+) %", text)
    assert opencv and abs(float(opencv.group(1))) < 1 and abs(float(opencv.group(2))) < 1


def test_the_pooled_sigma_over_spread_is_one_and_inside_its_range_for_honest_sigmas():
    """Windows drawn with known sigmas: the pooled ratio is near 1 and within its 95 % range 95 % of the time;
    sigmas twice too wide read near 2."""
    rng = np.random.default_rng(0)
    inside, ratios, wide = 0, [], []
    for _ in range(1000):
        sigma = rng.uniform(0.5, 2.0, 9)
        x = rng.normal(0.0, 1.0, (3, 9)) * sigma
        ratio, low, high = bench_realdata.pooled_ratio(x.std(axis=0, ddof=1), sigma, 3)
        inside += low < ratio < high
        ratios.append(ratio)
        wide.append(bench_realdata.pooled_ratio(x.std(axis=0, ddof=1), 2 * sigma, 3)[0])
    assert 0.93 < inside / 1000 < 0.97
    assert abs(np.median(ratios) - 1.0) < 0.05
    assert abs(np.median(wide) - 2.0) < 0.1


def test_windows_that_share_one_imus_terms_are_judged_by_what_differs_between_them():
    """Three windows shifted by one IMU's terms (the same delta, each window's own effect) and their own noise: the
    windows' difference over its sigma is standard normal, the expected spread is the spread's mean square, and the
    shared part is what the mean effect carries (a simulation of the model ``consistency_rows`` states)."""
    rng = np.random.default_rng(1)
    own = np.array([1.0, 0.5, 2.0])
    effects = rng.normal(size=(3, 1, 6)) + 3.0  # mostly common: the case the windows' spread cannot see
    spread = np.diag(rng.uniform(0.2, 1.0, 6))
    draws = 40_000
    delta = rng.multivariate_normal(np.zeros(6), spread, draws)
    x = delta @ effects[:, 0].T + rng.normal(size=(draws, 3)) * np.sqrt(own)
    _, expected, shared = bench_realdata._agreement(x[0], own, effects, [spread])
    mean = effects[:, 0].mean(axis=0)
    assert shared == pytest.approx(mean @ spread @ mean)
    assert expected == pytest.approx(np.mean(x.var(axis=1, ddof=1)), rel=0.03)
    assert expected < 0.2 * np.mean(own + np.einsum("wi,ij,wj->w", effects[:, 0], spread, effects[:, 0]))
    largest = np.array([bench_realdata._agreement(row, own, effects, [spread])[0] for row in x[:4000]])
    # the largest of three pairs' |z|: each standard normal, so below 2.39 in about 95 % of draws (1 - 3 * 0.0168)
    assert 0.93 < np.mean(largest < 2.39) < 0.97


def test_a_joint_extrinsic_turned_into_the_published_frame_is_compared_there():
    """A joint run whose principal point sits 7 px left of the published one, and whose extrinsic is the extrinsic
    task's seen from that camera's frame: turned back, it lands where the extrinsic task's did, 0 sigma from it."""
    from vical.geometry import CameraModel, camera_frame_turn

    published = CameraModel("radtan", 752, 480, 458.654, 457.296, 367.215, 248.375, np.array([-0.283, 0.074, 0, 0]))
    joint_camera = published.with_intrinsics(published.fx, published.fy, published.cx - 7.0, published.cy,
                                             published.dist)  # fmt: skip
    turn = np.eye(4)
    turn[:3, :3] = camera_frame_turn(joint_camera, published)
    T_extrinsic = bench_realdata.EUROC["cam0"]
    sigmas = dict.fromkeys(("rot_x", "rot_y", "rot_z", "t_x", "t_y", "t_z"), 1e-3)
    joint = {"T_cam_imu": (np.linalg.inv(turn) @ T_extrinsic).tolist(), "camera": joint_camera.to_dict(),
             "sigmas": sigmas}  # fmt: skip
    found = {
        (("cam0",), "joint", (0.0, 30.0)): {"cameras": {"cam0": joint}},
        (("cam0",), "extrinsic", (0.0, 30.0)): {"cameras": {"cam0": {"T_cam_imu": T_extrinsic.tolist()}}},
    }
    [row] = bench_realdata.published_frame_rows(found, {"cam0": published})
    assert re.search(r"turned 0\.8\d\d deg: EuRoC 0\.00\d deg 0\.00 mm Basalt 0\.3\d\d deg .* sigma 0\.0\d ", row), row
    assert bench_realdata.pose_error(np.array(joint["T_cam_imu"]), T_extrinsic)[0] > 0.8  # untouched: 0.9 deg away
