"""Every app on a corpus of bad inputs: exit status 2, exactly one ``error:`` line that names the file, key or flag
at fault, no traceback, and nothing left behind (no file or directory created, no input changed).

The inputs are built once per module in ``inputs/``. Each case runs in an empty working directory. The apps
with a ``main(argv)`` run in-process; the Hydra apps run their console entry point in-process for the errors
they catch before Hydra starts (Hydra itself is never reached: ``hydra_main`` is replaced by a function that
fails the test), and by subprocess where Hydra's own behaviour is under test.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest
from test_app_train import TINY, composed
from test_io_samples import make_recording as make_small_recording

from vical.apps import calibrate, evaluate, export, record, sim_demo, train
from vical.calib.synthetic import Excitation, make_recording
from vical.data import ImuNoise, ImuSamples
from vical.geometry import CameraModel
from vical.io import save_recording, write_bag, write_euroc
from vical.io.csvfiles import write_corners_csv, write_imu_csv
from vical.io.kalibr import write_camchain_imucam, write_imu_yaml, write_target_yaml
from vical.rl.checkpoint import AGENT, CHECKPOINT
from vical.rl.trainer import train as run_training


@dataclass(frozen=True)
class Case:
    """``app`` run with ``argv`` (``{inputs}`` stands for the inputs folder); the error line holds ``names`` (one
    fragment, or a tuple of them)."""

    app: str
    argv: str
    names: str | tuple[str, ...]

    def fragments(self, inputs: Path) -> list[str]:
        names = (self.names,) if isinstance(self.names, str) else self.names
        return [n.replace("{inputs}", str(inputs)) for n in names]

    def args(self, inputs: Path) -> list[str]:
        return [a.replace("{inputs}", str(inputs)) for a in self.argv.split()]


def _write_text(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def _imu_rows(imu: ImuSamples) -> list[str]:
    return [f"{t},{','.join(f'{v:.9g}' for v in (*g, *a))}" for t, g, a in zip(imu.t, imu.gyro, imu.accel, strict=True)]


IMU_HEADER = "#timestamp [ns],w_x,w_y,w_z,a_x,a_y,a_z"


def _imu_csv(path: Path, rows: list[str]) -> None:
    _write_text(path, "\n".join([IMU_HEADER, *rows]) + "\n")


def _sensor_files(d: Path) -> None:
    """A synthetic recording as a recording directory, corner and IMU CSVs, Kalibr YAMLs, and damaged variants."""
    rec = make_recording(duration=4.0, imu_noise=ImuNoise(), pixel_sigma=0.3, seed=5)
    save_recording(rec, d / "rec")
    write_corners_csv(rec.frames, d / "corners.csv")
    write_imu_csv(rec.imu, d / "imu.csv")
    write_target_yaml(d / "target.yaml", rec.target)
    write_imu_yaml(d / "imu.yaml", rec.truth.imu_noise)
    camera = rec.truth.camera
    write_camchain_imucam(d / "camchain.yaml", camera, None, None)
    big = CameraModel(camera.distortion, 2 * camera.width, 2 * camera.height, *(2 * camera.intrinsics), camera.dist)
    write_camchain_imucam(d / "camchain_1280.yaml", big, None, None)
    rows = _imu_rows(rec.imu)
    _write_text(d / "imu_empty.csv", "")
    _imu_csv(d / "imu_header.csv", [])
    _imu_csv(d / "imu_nan.csv", [*rows[:50], rows[50].replace(rows[50].split(",")[3], "nan", 1), *rows[51:]])
    _imu_csv(d / "imu_truncated.csv", [*rows[:60], ",".join(rows[60].split(",")[:4])])
    conflicting = rows[40].split(",")
    _imu_csv(d / "imu_conflict.csv", [*rows[:41], ",".join([conflicting[0], "9.0", *conflicting[2:]]), *rows[41:]])
    ms = [f"{int(r.split(',')[0]) // 1_000_000}," + r.split(",", 1)[1] for r in rows]
    _imu_csv(d / "imu_ms.csv", ms)
    _imu_csv(d / "imu_degps.csv", _imu_rows(ImuSamples(rec.imu.t, np.degrees(rec.imu.gyro) * 3, rec.imu.accel)))
    _imu_csv(d / "imu_g.csv", _imu_rows(ImuSamples(rec.imu.t, rec.imu.gyro, rec.imu.accel / 9.80665)))
    _write_text(d / "corners_header.csv", "#timestamp [ns],point_id,u [px],v [px]\n")
    corners = (d / "corners.csv").read_text().splitlines()
    t, _, u, v = corners[5].split(",")
    _write_text(d / "corners_bad_id.csv", "\n".join([*corners[:5], f"{t},99,{u},{v}", *corners[6:]]) + "\n")
    still = make_recording(duration=4.0, imu_noise=ImuNoise(), seed=5, excitation=Excitation().scaled(rotation=0.0))
    write_corners_csv(still.frames, d / "corners_still.csv")
    write_imu_csv(still.imu, d / "imu_still.csv")
    _write_text(d / "target_malformed.yaml", "{target_type: checkerboard, targetRows: [6\n")
    _write_text(d / "target_missing.yaml", "target_type: checkerboard\ntargetRows: 6\ntargetCols: 7\n")
    _write_text(
        d / "target_circles.yaml", "target_type: circlegrid\ntargetRows: 6\ntargetCols: 7\nspacingMeters: 0.05\n"
    )
    imu_yaml = (d / "imu.yaml").read_text()
    _write_text(d / "imu_negative.yaml", imu_yaml.replace("gyroscope_noise_density: ", "gyroscope_noise_density: -"))
    _write_text(d / "camchain_malformed.yaml", "cam0:\n  camera_model: pinhole\n  intrinsics: [1, 2]\n")
    _write_text(d / "recording_not.yaml", "not a recording")


def _image_sources(d: Path) -> None:
    """A recording with images, its bag and EuRoC folder, and damaged variants; an image folder with a corrupt file."""
    small = make_small_recording()
    save_recording(small, d / "small")
    save_recording(make_small_recording(images=False), d / "small_no_images")
    write_target_yaml(d / "small_target.yaml", small.target)
    write_bag(small, d / "small.bag")
    data = (d / "small.bag").read_bytes()
    (d / "truncated.bag").write_bytes(data[: len(data) // 2])
    write_euroc(small, d / "euroc")
    first = sorted((d / "euroc" / "mav0" / "cam0" / "data").glob("*.png"))[0]
    first.write_bytes(b"not a PNG")
    images = d / "images"
    images.mkdir()
    for k, image in enumerate(small.frames.images[:3]):
        cv2.imwrite(str(images / f"{k}.png"), image)
    (images / "3.png").write_bytes(b"\x89PNG truncated")
    shutil.copytree(d / "small", d / "small_truncated")
    imu = d / "small_truncated" / "imu.npz"
    imu.write_bytes(imu.read_bytes()[:100])
    _write_text(d / "sim_malformed.yaml", "physics: {timestep: [\n")
    _write_text(d / "sim_negative.yaml", "physics: {timestep: -1.0}\n")
    _write_text(d / "a_file", "a file where a directory should be")
    _write_text(d / "full" / "mine.txt", "the user's file")


def _runs(d: Path) -> None:
    """vical-train runs: finished (with checkpoints), unfinished, with a truncated checkpoint, without one."""
    finished = d / "run_finished"
    run_training(composed([*TINY, "train.total_steps=300", f"run_dir={finished}"]))
    shutil.copytree(finished, d / "run_unfinished")
    (d / "run_unfinished" / AGENT).unlink()
    shutil.copytree(d / "run_unfinished", d / "run_truncated")
    checkpoint = d / "run_truncated" / CHECKPOINT
    checkpoint.write_bytes(checkpoint.read_bytes()[:1000])
    shutil.copytree(d / "run_unfinished", d / "run_no_checkpoint")
    (d / "run_no_checkpoint" / CHECKPOINT).unlink()


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("inputs")
    _sensor_files(d)
    _image_sources(d)
    _runs(d)
    return d


CALIBRATE = "vical-calibrate"
CSV = "{inputs}/corners.csv --imu-csv {inputs}/%s --target {inputs}/target.yaml --image-size 640 480"

CASES = [
    # file readers: CSVs
    Case(CALIBRATE, CSV % "imu_empty.csv", "imu_empty.csv holds no IMU samples"),
    Case(CALIBRATE, CSV % "imu_header.csv", "imu_header.csv holds no IMU samples"),
    Case(CALIBRATE, CSV % "imu_nan.csv", "imu_nan.csv, line 52: NaN or inf reading"),
    Case(CALIBRATE, CSV % "imu_truncated.csv", "imu_truncated.csv, line 62: expected 7 comma-separated fields"),
    Case(CALIBRATE, CSV % "imu_conflict.csv", "imu_conflict.csv: lines 42 and 43 share timestamp"),
    Case(CALIBRATE, CSV % "imu_ms.csv", "imu_ms.csv: median timestamp step"),
    Case(CALIBRATE, CSV % "imu_degps.csv", ("imu_degps.csv: gyro reads up to", "pass --gyro-unit deg/s")),
    Case(CALIBRATE, CSV % "imu_g.csv", ("imu_g.csv: median accelerometer norm is 1.03", "pass --accel-unit g")),
    Case(CALIBRATE, CSV % "imu_g.csv" + " --accel-unit g --gyro-unit deg/s", "look like rad/s; pass --gyro-unit rad/s"),
    Case(CALIBRATE, CSV % "imu.csv" + " --gyro-unit deg/s", "imu.csv: read as deg/s, the gyro peaks at"),
    Case(
        CALIBRATE,
        "{inputs}/corners_header.csv --imu-csv {inputs}/imu.csv --target {inputs}/target.yaml --image-size 640 480",
        "corners_header.csv holds no corner rows",
    ),
    Case(
        CALIBRATE,
        "{inputs}/corners_bad_id.csv --imu-csv {inputs}/imu.csv --target {inputs}/target.yaml --image-size 640 480",
        "corners_bad_id.csv, line 6: point id 99 is outside the target's ids",
    ),
    # Kalibr YAMLs
    Case(
        CALIBRATE, CSV.replace("target.yaml", "target_malformed.yaml") % "imu.csv", "target_malformed.yaml is not valid"
    ),
    Case(CALIBRATE, CSV.replace("target.yaml", "target_missing.yaml") % "imu.csv", "'rowSpacingMeters' is missing"),
    Case(CALIBRATE, CSV.replace("target.yaml", "target_circles.yaml") % "imu.csv", "target_circles.yaml"),
    Case(CALIBRATE, CSV % "imu.csv" + " --imu-yaml {inputs}/imu_negative.yaml", "gyroscope_noise_density"),
    Case(
        CALIBRATE,
        "{inputs}/rec --task extrinsic --intrinsics {inputs}/camchain_malformed.yaml",
        "camchain_malformed.yaml",
    ),
    Case(CALIBRATE, "{inputs}/rec --task extrinsic --intrinsics {inputs}/camchain_1280.yaml", "calibrates 1280 x 960"),
    # image sources: bags, EuRoC folders, image folders
    Case(CALIBRATE, "{inputs}/truncated.bag --target {inputs}/small_target.yaml", "truncated.bag cannot be read"),
    Case(
        CALIBRATE,
        "{inputs}/small.bag --target {inputs}/small_target.yaml --imu-topic /nope",
        "small.bag: topic /nope is missing",
    ),
    Case(CALIBRATE, "{inputs}/euroc --target {inputs}/small_target.yaml --task intrinsic", "cannot decode the image"),
    Case(CALIBRATE, "{inputs}/images --target {inputs}/small_target.yaml --task intrinsic", "3.png: cannot decode"),
    Case(CALIBRATE, "{inputs}/images --target {inputs}/small_target.yaml", "an image folder holds no IMU data"),
    # the data, the motion and the settings
    Case(
        CALIBRATE,
        "{inputs}/corners_still.csv --imu-csv {inputs}/imu_still.csv --target {inputs}/target.yaml "
        "--task extrinsic --intrinsics {inputs}/camchain.yaml",
        "does not rotate enough",
    ),
    Case(
        CALIBRATE,
        CSV.replace("640 480", "100 100") % "imu.csv",
        "outside the image size 100 x 100 px given as --image-size 100 100",
    ),
    Case(CALIBRATE, CSV.replace(" --image-size 640 480", "") % "imu.csv", "the image size is unknown"),
    Case(CALIBRATE, "{inputs}/missing", "missing does not exist"),
    Case(CALIBRATE, "{inputs}/rec --task extrinsic", "--intrinsics"),
    Case(CALIBRATE, "{inputs}/rec --task nope", "argument --task: invalid choice: 'nope'"),
    Case(CALIBRATE, "{inputs}/rec --frame-stride 0", "argument --frame-stride: must be an integer >= 1, got '0'"),
    Case(CALIBRATE, "{inputs}/rec --max-time-offset inf", "argument --max-time-offset: must be a number >= 0"),
    Case(CALIBRATE, "{inputs}/rec --huber -1", "argument --huber: must be a number > 0"),
    Case(CALIBRATE, "{inputs}/rec --image-size 640", "argument --image-size: expected 2 arguments"),
    # bad out paths
    Case(CALIBRATE, "{inputs}/rec --out {inputs}/a_file", "--out {inputs}/a_file is a file"),
    Case(CALIBRATE, "{inputs}/rec --out {inputs}/a_file/calib", "--out {inputs}/a_file/calib cannot be created"),
    Case(CALIBRATE, "{inputs}/rec --out {inputs}/full", "--out {inputs}/full already holds files"),
    Case(CALIBRATE, "{inputs}/rec --out {inputs} --overwrite", "holds the input"),
    # vical-export
    Case(
        "vical-calibrate",
        "{inputs}/euroc --target {inputs}/target.yaml --cameras cam0,cam1",
        "--cameras names cam1, but {inputs}/euroc has cam0 (its camN folders); name cameras it has",
    ),
    Case("vical-export", "{inputs}/small_no_images --out out", "the recording has no images"),
    Case("vical-export", "{inputs}/euroc --out out", "euroc is not a vical recording directory"),
    Case("vical-export", "{inputs}/small_truncated --out out", "small_truncated/imu.npz has 100 bytes"),
    Case("vical-export", "{inputs}/small --out {inputs}/a_file", "--out {inputs}/a_file is a file"),
    Case("vical-export", "{inputs}/small --out {inputs}/full", "--out {inputs}/full exists and is not empty"),
    Case("vical-export", "{inputs}/small", "the following arguments are required: --out"),
    # vical-sim-demo
    Case("vical-sim-demo", "--config {inputs}/missing.yaml", "--config {inputs}/missing.yaml"),
    Case("vical-sim-demo", "--config {inputs}/sim_malformed.yaml", "sim_malformed.yaml is not valid YAML"),
    Case("vical-sim-demo", "--config {inputs}/sim_negative.yaml", "sim.physics.timestep must be"),
    Case("vical-sim-demo", "--steps -1", "argument --steps: must be an integer >= 0"),
    # vical-record: checked before Hydra starts
    Case("vical-record", "out={inputs}/full", "out={inputs}/full already exists"),
    Case("vical-record", "out={inputs}/a_file overwrite=true", "out={inputs}/a_file is a file"),
    Case(
        "vical-record",
        "out={inputs}/a_file/rec",
        "out={inputs}/a_file/rec cannot be created: {inputs}/a_file is a file",
    ),
    Case("vical-record", "steps=foo", "steps must be a non-empty list"),
    Case("vical-record", "steps=[[0.1,0.0]]", "steps[0] must be 6 finite numbers"),
    Case("vical-record", "seed=abc", "seed must be an integer >= 0, got 'abc'"),
    Case("vical-record", "sim.physics.timestep=-1", "sim.physics.timestep must be a number in (0.0, 0.01]"),
    Case("vical-record", "settle_time=-1", "settle_time must be a number in [0.0, 60.0]"),
    Case("vical-record", "sensor.backend=nope", "sensor.backend must be one of"),
    Case(
        "vical-record",
        "sensor.camera.distortion=eucm sensor.camera.beta.mean=-1",
        "sensor.camera.beta.mean must be > 0 for the eucm model, got -1",
    ),
    Case("vical-record", "mode=static", "mode must be one of ['steps', 'static_imu'], got 'static'"),
    Case("vical-record", "mode=static_imu static_duration=0", "static_duration must be a number in (0.0, 172800.0]"),
    Case("vical-record", "mode=static_imu static_duration=1e9", "static_duration must be a number in (0.0, 172800.0]"),
    Case("vical-record", "sensor=stereo sensor.rig=5", "sensor.rig must be a list of the rig's other cameras"),
    Case("vical-record", "+sensor.rig=[{baseline:0.1}]", "sensor.rig[0]: unknown setting(s) ['baseline']"),
    Case(
        "vical-record",
        "sensor=stereo sensor.rig.0.position_std=[0.1,-1,0]",
        "sensor.rig[0].position_std must be non-negative, got [0.1, -1.0, 0.0]",
    ),
    Case("vical-record", "nokey=1", "Could not override 'nokey'. To append to your config use +nokey=1"),
    Case("vical-record", "sim=nope", "Could not find 'sim/nope'; the available options in 'sim' are: default"),
    Case("vical-record", "steps=[", "cannot parse the override 'steps=['"),
    # vical-train: checked before Hydra creates a run directory
    Case("vical-train", "train.total_steps=0", "train.total_steps must be a number in [1, inf), got 0"),
    Case("vical-train", "agent.gamma=2", "agent.gamma"),
    Case("vical-train", "train.clone_updates=100", "train.clone_updates must be 0 without train.demonstrator"),
    Case(
        "vical-train",
        "+experiment=train_practitioner_from_planner train.demonstrator._target_=vical.nope",
        "train.demonstrator: vical.nope could not be built",
    ),
    Case("vical-train", "+experiment=train_distill_rate_planner train.distill.beta=2", "train.distill.beta must be"),
    Case(
        "vical-train",
        "+experiment=train_distill_rate_planner train.demonstrator._target_=vical.nope",
        "train.demonstrator: vical.nope could not be built",
    ),
    Case("vical-train", "agent=nope", "Could not find 'agent/nope'; the available options in 'agent' are: sac"),
    Case("vical-train", "agent.nope=1", "Could not override 'agent.nope'"),
    Case("vical-train", "run_dir={inputs}/a_file", "run_dir={inputs}/a_file is a file"),
    Case("vical-train", "hydra.run.dir={inputs}/a_file", "hydra.run.dir={inputs}/a_file is a file"),
    Case("vical-train", "resume={inputs}/missing", "resume must be a run directory of vical-train"),
    Case(
        "vical-train", "resume={inputs}/run_finished agent=sac_authors", "agent=sac_authors (a config group selection"
    ),
    Case("vical-train", "resume={inputs}/run_finished train.total_steps=100", "train.total_steps=100 is below the 300"),
    Case("vical-train", "resume={inputs}/run_unfinished train.total_steps=100", "train.total_steps=100 is below step"),
    Case("vical-train", "resume={inputs}/run_truncated", "run_truncated/checkpoint.pt cannot be read as a checkpoint"),
    Case("vical-train", "resume={inputs}/run_no_checkpoint", "run_no_checkpoint has no checkpoint yet"),
    Case("vical-train", "hydra/launcher=nope", "Could not find 'hydra/launcher/nope'"),
]

IN_PROCESS = {"vical-calibrate": calibrate, "vical-export": export, "vical-sim-demo": sim_demo}
HYDRA_APPS = {"vical-record": record, "vical-train": train, "vical-evaluate": evaluate}


def snapshot(*folders: Path) -> dict[str, tuple[int, int]]:
    """Every path under ``folders`` with its size and modification time."""
    return {str(p): (p.stat().st_size, p.stat().st_mtime_ns) for f in folders for p in sorted(f.rglob("*"))}


def _refuse_hydra() -> None:
    raise AssertionError("the error was not caught before Hydra started")


def run_in_process(case: Case, argv: list[str], monkeypatch, capsys) -> tuple[int, str]:
    """Exit status and all output of the app's console entry point run in this process."""
    if case.app in IN_PROCESS:
        status = IN_PROCESS[case.app].main(argv)
    else:
        module = HYDRA_APPS[case.app]
        monkeypatch.setattr(module, "hydra_main", _refuse_hydra)
        monkeypatch.setattr(sys, "argv", [case.app, *argv])
        with pytest.raises(SystemExit) as exit_:
            module.main()
        status = exit_.value.code
    captured = capsys.readouterr()
    return status, captured.out + captured.err


def assert_one_error_line(app: str, output: str, fragments: list[str]) -> None:
    assert "Traceback" not in output, output
    errors = [line for line in output.replace("\r", "\n").splitlines() if "error:" in line]
    assert len(errors) == 1, output
    assert errors[0].startswith(f"{app}: error: "), errors[0]
    for fragment in fragments:
        assert fragment in errors[0], errors[0]


@pytest.mark.parametrize("case", CASES, ids=[f"{c.app}:{c.argv.replace('{inputs}/', '')}" for c in CASES])
def test_a_bad_input_is_one_error_line_with_exit_status_2_and_leaves_nothing(
    case, inputs, tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)
    before = snapshot(inputs)
    status, output = run_in_process(case, case.args(inputs), monkeypatch, capsys)
    assert status == 2, output
    assert_one_error_line(case.app, output, case.fragments(inputs))
    assert list(tmp_path.iterdir()) == [] and snapshot(inputs) == before


# The console scripts themselves, where Hydra's behaviour is under test: its own errors, a run directory it made.
SUBPROCESS_CASES = [
    Case("vical-train", "nokey=1", "Could not override 'nokey'"),
    Case("vical-train", "env._target_=nope.nope", "Error locating target 'nope.nope'"),  # after Hydra made runs/<time>
    Case("vical-record", "seed=abc", "seed must be an integer >= 0, got 'abc'"),
    Case("vical-evaluate", "sim=nope", "Could not find 'sim/nope'"),
    Case("vical-evaluate", "policy=nope", "unknown policy 'nope'"),
    Case("vical-evaluate", "episodes=0", "episodes must be an integer >= 1, got 0"),
    # the output checked before the first of 50 episodes (minutes of work): the timeout would catch it later
    Case("vical-evaluate", "out={inputs}/a_file/x episodes=50", "out={inputs}/a_file/x cannot be created"),
    Case("vical-evaluate", "out={inputs}/full/mine.txt", "out={inputs}/full/mine.txt exists and is not a directory"),
    Case("vical-evaluate", "stop.rule=maybe", "stop.rule must be one of ('policy', 'information')"),
    Case("vical-evaluate", "stop=information stop.run_dir={inputs}/nowhere", "stop=information: no trained agent at"),
    Case("vical-evaluate", "stop=information workspace=paper", ("paper_policy", "trained on the coverage state")),
    Case("vical-evaluate", "policy=greedy_information policy.samples=-1", "policy.samples must be an integer >= 0"),
    Case("vical-evaluate", "sensor.camera.hfov.mean=5", "sensor.camera.hfov.mean must be a number in (0.0, 3.14"),
    Case("vical-evaluate", "stop=information stop.max_steps=0", "stop.max_steps must be null or an integer >= 1"),
    Case("vical-evaluate", "stop=information stop.horizon_s=-5", "stop.horizon_s must be null or a time > 0"),
    Case("vical-evaluate", "stop=information stop.horizon_s=0.2", "stop.horizon_s must be at least one step"),
    Case("vical-evaluate", "sensor.imu.gyro_noise=0", "sensor.imu.gyro_noise must be a number in (0.0, inf)"),
    Case("vical-collect", "limits.horizon_s=0.2 out=c", "limits.horizon_s must be at least one step of recording"),
    Case("vical-collect", "sensor.imu.accel_noise=0 out=c", "sensor.imu.accel_noise must be a number in (0.0, inf)"),
    Case("vical-guide", "limits.time_limit=0.5 page.enabled=false out=c", "limits.horizon_s must be at least one step"),
    Case("vical-train", "env=information env.information.tolerances.rotation_deg=0", "tolerances.rotation_deg must be"),
    Case("vical-train", "env=information env.information.tolerances.focal_px=-1", "tolerances.focal_px must be a"),
    Case(
        "vical-evaluate",
        "sensor=practitioner sensor.products.imu_noise_scale.low=20",
        "sensor.products.imu_noise_scale.high must be a number >= sensor.products.imu_noise_scale.low",
    ),
]


@pytest.mark.integration
@pytest.mark.parametrize(
    "case", SUBPROCESS_CASES, ids=[f"{c.app}:{c.argv.replace('{inputs}/', '')}" for c in SUBPROCESS_CASES]
)
def test_the_console_scripts_report_hydras_errors_and_their_own_in_one_line(case, inputs, tmp_path):
    before = snapshot(inputs)
    done = subprocess.run(
        [str(Path(sys.executable).parent / case.app), *case.args(inputs)],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2, done.stdout + done.stderr
    assert_one_error_line(case.app, done.stdout + done.stderr, case.fragments(inputs))
    assert list(tmp_path.iterdir()) == [] and snapshot(inputs) == before


def test_a_flaw_the_reader_fixes_is_one_warning_line_and_the_calibration_goes_on(inputs, tmp_path):
    rows = (inputs / "imu.csv").read_text().splitlines()
    rows[20], rows[21] = rows[21], rows[20]
    _write_text(tmp_path / "imu.csv", "\n".join([*rows, rows[-1]]) + "\n")  # unsorted, and the last row twice
    argv = CSV.replace("{inputs}/%s", str(tmp_path / "imu.csv")).replace("{inputs}", str(inputs)).split()
    done = subprocess.run(
        [str(Path(sys.executable).parent / CALIBRATE), *argv, "--imu-yaml", str(inputs / "imu.yaml"), "--no-report"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    path = tmp_path / "imu.csv"
    assert done.stderr.splitlines() == [
        f"warning: {path}: timestamps are not sorted (line 22 is earlier than line 21); sorted",
        f"warning: {path}: 1 duplicated rows (same timestamp and data, e.g. line {len(rows) + 1}) dropped",
    ]


@pytest.mark.parametrize(
    ("err", "line"),
    [
        (FileNotFoundError(2, "No such file or directory", "imu.yaml"), "imu.yaml: no such file or directory"),
        (
            FileExistsError("--out board holds target.pdf; pass --overwrite"),
            "--out board holds target.pdf; pass --overwrite",
        ),
        (IsADirectoryError(21, "Is a directory"), "[Errno 21] Is a directory"),  # no path to name: the system's line
    ],
)
def test_a_file_the_command_cannot_open_is_one_line_naming_the_path_or_vicals_own_message(err, line, capsys):
    """``argparse_main``: an ``OSError`` with a path gives the path and the reason; one vical raised with its own
    message (no path) gives the message, never ``None: ...``."""
    import argparse

    from vical.apps.cli import argparse_main

    def run(args):
        raise err

    assert argparse_main("vical-x", argparse.ArgumentParser(), run, (), {}, []) == 2
    assert capsys.readouterr().err.strip() == f"vical-x: error: {line}"
