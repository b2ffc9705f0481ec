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
