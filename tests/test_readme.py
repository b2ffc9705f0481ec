"""The README's real-rig example runs as written: its four commands, exactly as the page shows them (the
``.venv/bin/`` of the page is this interpreter's), in one working directory, each exiting 0; the IMU noise it
measures is the simulated IMU's and the stereo rig it calibrates is the recorded one."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from vical.io.kalibr import read_imu_yaml
from vical.io.kalibr_chain import read_chain
from vical.io.recording import load_recording

README = Path(__file__).resolve().parents[1] / "README.md"


def block_with(command: str) -> list[str]:
    """The commands of the README's ``bash`` block that runs ``command`` (comments dropped), in order."""
    blocks = re.findall(r"^```bash\n(.*?)^```", README.read_text(), flags=re.MULTILINE | re.DOTALL)
    (block,) = [b for b in blocks if command in b]
    return [line.split("#")[0].strip() for line in block.splitlines() if line.strip()]


@pytest.mark.integration
def test_the_readme_real_rig_example_runs_as_written(tmp_path):
    commands = block_with("vical-imu-noise")
    assert [shlex.split(c)[0] for c in commands] == [
        ".venv/bin/vical-record", ".venv/bin/vical-imu-noise", ".venv/bin/vical-record", ".venv/bin/vical-calibrate",
    ]  # fmt: skip
    for command in commands:
        program, *args = shlex.split(command)
        done = subprocess.run([str(Path(sys.executable).parent / Path(program).name), *args], cwd=tmp_path,
                              capture_output=True, text=True, timeout=600)  # fmt: skip
        assert done.returncode == 0, f"{command}\n{done.stderr}"
    measured = read_imu_yaml(tmp_path / "imu_noise" / "imu.yaml")
    truth = load_recording(tmp_path / "stereo").truth
    assert measured.gyro_noise_density == pytest.approx(truth.imu_noise.gyro_noise_density, rel=0.1)
    assert measured.accel_noise_density == pytest.approx(truth.imu_noise.accel_noise_density, rel=0.1)
    rec = load_recording(tmp_path / "stereo")
    T_c1_c0 = rec.truth_of("cam1").T_cam_imu @ np.linalg.inv(rec.truth.T_cam_imu)
    found = read_chain(tmp_path / "calib" / "camchain-imucam.yaml")["cam1"].T_cn_cnm1
    assert np.linalg.norm(found[:3, 3] - T_c1_c0[:3, 3]) < 0.002
