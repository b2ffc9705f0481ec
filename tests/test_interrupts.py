"""Ctrl-C and SIGTERM in the commands: one line saying what was kept, exit 130 (Ctrl-C) or 143 (SIGTERM), nothing
half-written. In process, the interrupt is raised through a hook at a stage (writing, the Allan computation);
in the integration tier, a real signal is sent when the command prints the marker of a stage."""

import os
import re
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from imu_streams import static_stream
from stopped_collections import default_sigint

from vical.apps.cli import write_faults_in_one_line
from vical.apps.entry import Terminated, interrupts_as_raised
from vical.calib.synthetic import make_recording
from vical.data import ImuNoise
from vical.io.csvfiles import write_imu_csv
from vical.io.recording import save_recording

INTERRUPTS = [("KeyboardInterrupt", 130, "Ctrl-C"), ("Terminated", 143, "SIGTERM")]


def entry_point(name: str):
    """The console script's function in ``vical.apps.entry`` (imported here: the module is what is tested)."""
    import vical.apps.entry

    return getattr(vical.apps.entry, name)


def interrupt(kind: str):
    import vical.apps.entry

    error = KeyboardInterrupt if kind == "KeyboardInterrupt" else vical.apps.entry.Terminated

    def hook(*args, **kwargs):
        raise error()

    return hook


def run_entry(function, argv: list, monkeypatch, capsys) -> tuple[int, list[str]]:
    monkeypatch.setattr(sys, "argv", [str(a) for a in argv])
    with pytest.raises(SystemExit) as done:
        function()
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    return done.value.code, lines


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    rec = make_recording(duration=4.0, imu_noise=ImuNoise(), pixel_sigma=0.3, seed=2)
    return save_recording(rec, tmp_path_factory.mktemp("rec") / "rec")


@pytest.mark.parametrize(("kind", "status", "name"), INTERRUPTS)
def test_calibrate_interrupted_while_writing_its_report_leaves_out_as_it_was(
    kind, status, name, recording, tmp_path, monkeypatch, capsys
):
    from vical.apps import calibrate_outputs

    monkeypatch.setattr(calibrate_outputs, "write_report", interrupt(kind))
    out = tmp_path / "out"
    code, lines = run_entry(entry_point("calibrate"), ["vical-calibrate", recording, "--out", out], monkeypatch, capsys)
    assert code == status
    assert lines == [f"vical-calibrate: interrupted ({name}); --out {out} is as it was: the outputs are written "
                     "whole or not at all"]  # fmt: skip
    assert not out.exists() and not [p for p in tmp_path.iterdir() if p.name != "out"]


@pytest.mark.parametrize(("kind", "status", "name"), INTERRUPTS)
def test_imu_noise_interrupted_in_the_allan_computation_writes_nothing(
    kind, status, name, tmp_path, monkeypatch, capsys
):
    from vical.apps import imu_noise

    path = tmp_path / "static.csv"
    write_imu_csv(static_stream(600, 1), path)
    monkeypatch.setattr(imu_noise, "identify_noise", interrupt(kind))
    out = tmp_path / "out"
    code, lines = run_entry(entry_point("imu_noise"), ["vical-imu-noise", path, "--out", out], monkeypatch, capsys)
    assert code == status
    assert lines[-1] == (f"vical-imu-noise: interrupted ({name}); --out {out} is as it was: the outputs are "
                         "written whole or not at all")  # fmt: skip
    assert not out.exists()


PROGRESS_BAR = re.compile(r"\d+%\|")


def signal_at_marker(
    app: str, args: list[str], marker: str, sig: int, cwd: Path | None = None
) -> tuple[int, list[str], str]:
    """Run the console script ``app``, send ``sig`` when its stderr shows ``marker`` (the stage's line, never after a
    sleep); its exit status, its stderr lines that start with its name (its progress bars left out: they carry its
    name too), and its whole stderr."""
    proc = subprocess.Popen([str(Path(sys.executable).parent / app), *args], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, cwd=cwd, preexec_fn=default_sigint)  # fmt: skip
    seen = ""
    while marker not in seen:
        char = proc.stderr.read(1)
        assert char, f"{app} ended before {marker!r}: {seen}"
        seen += char
    os.kill(proc.pid, sig)
    stderr = seen + proc.stderr.read()
    status = proc.wait(timeout=120)
    lines = stderr.replace("\r", "\n").splitlines()
    return status, [line for line in lines if line.startswith(app) and not PROGRESS_BAR.search(line)], stderr


SIGNALS = [(signal.SIGINT, 130, "Ctrl-C"), (signal.SIGTERM, 143, "SIGTERM")]


def as_it_was(app: str, where: str, name: str) -> str:
    return f"{app}: interrupted ({name}); {where} is as it was: the outputs are written whole or not at all"


@pytest.mark.integration
@pytest.mark.parametrize(("sig", "status", "name"), [(signal.SIGINT, 130, "Ctrl-C"), (signal.SIGTERM, 143, "SIGTERM")])
def test_a_real_signal_during_the_allan_computation_stops_vical_imu_noise_in_one_line(sig, status, name, tmp_path):
    path = tmp_path / "static.csv"
    write_imu_csv(static_stream(3 * 3600, 1), path)  # long enough to still be computing when the signal lands
    out = tmp_path / "out"
    command = [str(path), "--out", str(out)]
    status_seen, lines, stderr = signal_at_marker("vical-imu-noise", command, "Allan deviation", sig)  # progress bar
    assert status_seen == status, stderr
    assert lines == [f"vical-imu-noise: interrupted ({name}); --out {out} is as it was: the outputs are written "
                     "whole or not at all"], stderr  # fmt: skip
    assert "Traceback" not in stderr and not out.exists()


@pytest.fixture(scope="module")
def euroc_with_images(tmp_path_factory):
    """A rendered recording written as an EuRoC folder: vical-calibrate detects its corners (a progress bar)."""
    from test_app_calibrate_sources import record_rendered

    from vical.io import write_euroc, write_imu_yaml, write_target_yaml

    rec = record_rendered()
    root = tmp_path_factory.mktemp("euroc")
    write_euroc(rec, root / "euroc")
    write_target_yaml(root / "target.yaml", rec.target)
    write_imu_yaml(root / "imu.yaml", rec.truth.imu_noise)
    return root


@pytest.mark.integration
@pytest.mark.parametrize(("sig", "status", "name"), [(signal.SIGINT, 130, "Ctrl-C"), (signal.SIGTERM, 143, "SIGTERM")])
def test_a_real_signal_during_the_detection_stops_vical_calibrate_in_one_line(sig, status, name, euroc_with_images):
    root = euroc_with_images
    out = root / f"out-{name}"
    command = [str(root / "euroc"), "--target", str(root / "target.yaml"), "--imu-yaml", str(root / "imu.yaml"),
               "--out", str(out)]  # fmt: skip
    status_seen, lines, stderr = signal_at_marker("vical-calibrate", command, "EuRoC cam0", sig)  # the detection's bar
    assert status_seen == status, stderr
    assert lines == [f"vical-calibrate: interrupted ({name}); --out {out} is as it was: the outputs are written "
                     "whole or not at all"], stderr  # fmt: skip
    assert "Traceback" not in stderr and not out.exists()


@pytest.mark.integration
@pytest.mark.parametrize(("sig", "status", "name"), SIGNALS)
def test_a_real_signal_while_a_static_imu_is_generated_stops_vical_record_in_one_line(sig, status, name, tmp_path):
    out = tmp_path / "static"
    status_seen, lines, stderr = signal_at_marker("vical-record", ["mode=static_imu", f"out={out}"], "vical-record:",
                                                  sig)  # fmt: skip
    assert status_seen == status, stderr
    assert lines == [as_it_was("vical-record", f"out={out}", name)], stderr
    assert "Traceback" not in stderr and not out.exists()
    assert_next_run_leaves_no_temporary(["mode=static_imu", "static_duration=60", f"out={out}"], tmp_path)


def assert_next_run_leaves_no_temporary(args: list[str], folder: Path) -> None:
    """A signal that lands while the temporary output is being created (inside mkdtemp) leaves it, named as a
    temporary of a process that is gone: the next run to the same ``out`` removes it, and succeeds."""
    done = subprocess.run([str(Path(sys.executable).parent / "vical-record"), *args, "progress=false"],
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert not [p for p in folder.iterdir() if ".tmp-" in p.name]


@pytest.mark.integration
@pytest.mark.parametrize(("sig", "status", "name"), SIGNALS)
def test_a_real_signal_while_frames_are_rendered_stops_vical_record_in_one_line(sig, status, name, tmp_path):
    out = tmp_path / "rec"
    args = ["sensor.backend=render", "images=true", f"out={out}"]
    status_seen, lines, stderr = signal_at_marker("vical-record", args, "vical-record:", sig)  # the steps' bar
    assert status_seen == status, stderr
    assert lines == [as_it_was("vical-record", f"out={out}", name)], stderr
    assert "Traceback" not in stderr and not out.exists()
    assert_next_run_leaves_no_temporary(["steps=[[0.0,0.04,0.0,0.0,0.0,0.1]]", f"out={out}"], tmp_path)


@pytest.fixture(scope="module")
def recording_with_images(tmp_path_factory):
    """A recording whose 150 noise images are slow to encode: the export is still writing its bag when signalled."""
    from dataclasses import replace

    from vical.data import CameraFrames

    rec = make_recording(duration=15.0, imu_noise=ImuNoise(), pixel_sigma=0.3, seed=3)
    images = np.random.default_rng(0).integers(0, 256, (len(rec.frames), 480, 640), dtype=np.uint8)
    frames = CameraFrames(rec.frames.t, rec.frames.corners, rec.frames.ids, images)
    return save_recording(replace(rec, frames=frames), tmp_path_factory.mktemp("rec") / "rec")


@pytest.mark.integration
@pytest.mark.parametrize(("sig", "status", "name"), SIGNALS)
def test_a_real_signal_while_the_bag_is_written_stops_vical_export_in_one_line(
    sig, status, name, recording_with_images, tmp_path
):
    out = tmp_path / "kalibr_in"
    args = [str(recording_with_images), "--out", str(out)]
    status_seen, lines, stderr = signal_at_marker("vical-export", args, "writing data.bag", sig)
    assert status_seen == status, stderr
    assert lines == [as_it_was("vical-export", f"--out {out}", name)], stderr
    assert "Traceback" not in stderr and not out.exists()


@pytest.mark.integration
@pytest.mark.parametrize(("sig", "status", "name"), SIGNALS)
def test_a_real_signal_during_the_episodes_stops_vical_evaluate_in_one_line(sig, status, name, tmp_path):
    out = tmp_path / "evaluation"
    args = ["episodes=3", "budgets=[]", f"out={out}"]
    status_seen, lines, stderr = signal_at_marker("vical-evaluate", args, "episodes:", sig, cwd=tmp_path)
    assert status_seen == status, stderr
    assert lines == [as_it_was("vical-evaluate", f"out={out}", name)], stderr
    assert "Traceback" not in stderr and sorted(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("kind", "status", "name"), INTERRUPTS)
def test_export_interrupted_while_replacing_an_export_keeps_the_old_one_whole(
    kind, status, name, tmp_path, monkeypatch, capsys
):
    """--overwrite over a complete export, stopped while the new bag is written: every old file as it was (the
    EuRoC folder already written anew included), no temporary left."""
    from dataclasses import replace

    from vical.apps import export
    from vical.data import CameraFrames

    def with_images(seed: int) -> Path:
        rec = make_recording(duration=2.0, imu_noise=ImuNoise(), seed=seed)
        images = np.random.default_rng(seed).integers(0, 256, (len(rec.frames), 480, 640), dtype=np.uint8)
        frames = CameraFrames(rec.frames.t, rec.frames.corners, rec.frames.ids, images)
        return save_recording(replace(rec, frames=frames), tmp_path / f"rec{seed}")

    out = tmp_path / "kalibr_in"
    assert export.main([str(with_images(5)), "--out", str(out)]) == 0
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    capsys.readouterr()
    monkeypatch.setattr(export, "write_bag", interrupt(kind))
    argv = ["vical-export", with_images(6), "--out", out, "--overwrite"]  # another recording's export
    code, lines = run_entry(entry_point("export"), argv, monkeypatch, capsys)
    assert code == status
    assert lines == [as_it_was("vical-export", f"--out {out}", name)]
    assert {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    assert not [p for p in tmp_path.rglob("*") if ".tmp-" in p.name]


@pytest.mark.parametrize("kind", ["KeyboardInterrupt", "Terminated"])
def test_record_interrupted_while_replacing_a_recording_keeps_the_old_one_whole(kind, tmp_path, monkeypatch):
    """overwrite=true over a complete recording, stopped while the new one is written: the old one as it was."""
    from hydra import compose, initialize_config_dir

    from vical.apps import record as app

    def config(*overrides):
        with initialize_config_dir(config_dir=str(Path(app.CONF_DIR)), version_base="1.3"):
            return compose(config_name="record", overrides=list(overrides))

    out = tmp_path / "rec"
    short = ["steps=[[0.0,0.04,0.0,0.0,0.0,0.1]]", "settle_time=0.05", "progress=false", f"out={out}"]
    app.record(config(*short, "seed=1"))
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    monkeypatch.setattr(app, "write_recording_files", interrupt(kind))
    with pytest.raises(KeyboardInterrupt):
        app.record(config(*short, "seed=2", "overwrite=true"))
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec"]  # no temporary left beside it


@pytest.mark.integration
@pytest.mark.parametrize(("sig", "status", "name"), SIGNALS)
def test_a_real_signal_during_the_steps_stops_vical_sim_demo_in_one_line(sig, status, name):
    """Signalled once it printed its start (the marker: 'Panda at home', on stdout), while it moves 200 steps."""
    proc = subprocess.Popen([str(Path(sys.executable).parent / "vical-sim-demo"), "--steps", "200"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=default_sigint)  # fmt: skip
    assert proc.stdout.readline().startswith("Panda at home")
    os.kill(proc.pid, sig)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == status
    lines = [line for line in stderr.replace("\r", "\n").splitlines() if line]  # the line starts with a \r
    assert lines == [f"vical-sim-demo: interrupted ({name}); nothing was written"], stderr


@pytest.mark.parametrize(("kind", "status", "name"), INTERRUPTS)
def test_an_interrupt_while_the_command_is_imported_ends_in_one_line(kind, status, name, monkeypatch, capsys):
    """The entry point handles Ctrl-C and SIGTERM before the command's heavy imports (torch, GTSAM, MuJoCo)."""
    import vical.apps.entry

    monkeypatch.setattr(vical.apps.entry.importlib, "import_module", interrupt(kind))
    code, lines = run_entry(entry_point("calibrate"), ["vical-calibrate", "rec", "--out", "out"], monkeypatch, capsys)
    assert code == status
    assert lines == [as_it_was("vical-calibrate", "--out out", name)]


def _interrupted_while_a_lock_is_released(interrupt: KeyboardInterrupt) -> None:
    """What a signal does in the middle of ``threading.Condition``'s release (CI: the guide's ``ThreadPoolExecutor.
    submit`` at a decision): the lock is released, the interrupt is raised, and the ``with`` then releases it again."""
    lock = threading.Lock()
    with lock:
        lock.release()
        raise interrupt


@pytest.mark.parametrize("interrupt", [KeyboardInterrupt(), Terminated()], ids=["Ctrl-C", "SIGTERM"])
def test_an_error_an_interrupt_caused_is_raised_as_the_interrupt(interrupt):
    with pytest.raises(RuntimeError, match="release unlocked lock") as raised:  # the fault, as it comes
        _interrupted_while_a_lock_is_released(interrupt)
    assert raised.value.__context__ is interrupt
    with pytest.raises(KeyboardInterrupt) as raised, interrupts_as_raised():
        _interrupted_while_a_lock_is_released(interrupt)
    assert raised.value is interrupt  # Terminated stays SIGTERM's: status 143
    # the commands' writers' block lets it through as the interrupt (Hydra prints any other error as a traceback)
    with pytest.raises(KeyboardInterrupt) as raised, write_faults_in_one_line("vical-record", "out=", "x"):
        _interrupted_while_a_lock_is_released(interrupt)
    assert raised.value is interrupt
    with pytest.raises(RuntimeError, match="not an interrupt"), interrupts_as_raised():
        raise RuntimeError("not an interrupt")
