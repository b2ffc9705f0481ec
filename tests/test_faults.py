"""Faults at any moment, in every command: a real signal during the start-up (the interpreter's, the heavy imports',
the command's first steps), as a console script and as ``python -m``, alone and beside a busy process; each ends
with its exit status (130 Ctrl-C, 143 SIGTERM) and one line, never a traceback. A new console script is run here
by being listed in ``pyproject.toml`` (``test_every_console_script_is_faulted``)."""

import re
import signal
import subprocess
import sys
import time
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from imu_streams import static_stream
from stopped_collections import default_sigint, kill_if_running

from vical.calib.synthetic import make_recording
from vical.data import CameraFrames, ImuNoise
from vical.io.csvfiles import write_imu_csv
from vical.io.euroc import read_euroc
from vical.io.kalibr import read_target_yaml
from vical.io.recording import save_recording

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent

# Seconds after vical's start-up handling is in place (the first ~50 ms of a process are the interpreter's own
# start-up, before any of vical runs: a SIGTERM there takes its default action, 143 without a line): at once, during
# numpy's, torch's, GTSAM's and MuJoCo's imports (~0.2-1.5 s on 2 cores), the command's first steps. Every command
# below runs for longer than the last moment.
MOMENTS = (0.0, 0.1, 0.3, 0.6, 1.0, 1.5)
SIGNALS = {signal.SIGINT: (130, "Ctrl-C"), signal.SIGTERM: (143, "SIGTERM")}
PROGRESS_BAR = re.compile(r"\d+%\|")


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    """A recording, one with 900 images (slow to export: ~2-3 s), and a resting IMU's CSV (slow to analyse)."""
    folder = tmp_path_factory.mktemp("inputs")
    rec = make_recording(duration=4.0, imu_noise=ImuNoise(), pixel_sigma=0.3, seed=2)
    long = make_recording(duration=90.0, imu_noise=ImuNoise(), pixel_sigma=0.3, seed=3)
    images = np.random.default_rng(0).integers(0, 256, (len(long.frames), 480, 640), dtype=np.uint8)
    long = replace(long, frames=CameraFrames(long.frames.t, long.frames.corners, long.frames.ids, images))
    write_imu_csv(static_stream(1800, 1), folder / "static.csv")
    return {
        "recording": save_recording(rec, folder / "rec"),
        "with_images": save_recording(long, folder / "with_images"),
        "static": folder / "static.csv",
    }


def command_args(app: str, inputs: dict[str, Path], out: Path) -> list[str]:
    """Arguments with which ``app`` runs for several seconds, writing under ``out``."""
    return {
        "vical-calibrate": [str(inputs["recording"]), "--out", str(out / "calibration")],
        "vical-imu-noise": [str(inputs["static"]), "--out", str(out / "noise")],
        "vical-record": [f"out={out / 'recording'}", "images=true", "sensor.backend=render"],
        "vical-export": [str(inputs["with_images"]), "--out", str(out / "export")],
        "vical-evaluate": ["episodes=3", "budgets=[]", f"out={out / 'evaluation'}"],
        "vical-train": [f"run_dir={out / 'run'}"],
        "vical-sim-demo": ["--steps", "200"],
        "vical-collect": [f"out={out / 'collection'}", "policy=random_moving", "calibrate=false"],
        "vical-guide": [f"out={out / 'guide'}", "page.port=0", "page.linger=0"],
        "vical-target": ["--out", str(out / "target"), "--size", "0.088", "--paper", "A0"],  # ~5 s: an A0 sheet
    }[app]


def console_scripts() -> list[str]:
    return list(tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"])


def command_line(app: str, form: str) -> list[str]:
    """``app`` as its console script or as ``python -m vical.apps.<module>``."""
    if form == "script":
        return [str(BIN / app)]
    return [sys.executable, "-m", "vical.apps." + app.removeprefix("vical-").replace("-", "_")]


def catches_sigterm(pid: int) -> bool:
    """Whether process ``pid`` handles SIGTERM (its caught-signals mask in ``/proc``): from vical's start-up on."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("SigCgt:"):
            return bool(int(line.split()[1], 16) >> (signal.SIGTERM - 1) & 1)
    return False


def signal_after(cmd: list[str], seconds: float, sig: int, cwd: Path) -> tuple[int, str]:
    """Run ``cmd``, send ``sig`` ``seconds`` after it handles SIGTERM; its exit status and stderr."""
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=cwd,
                            preexec_fn=default_sigint)  # fmt: skip
    try:
        deadline = time.monotonic() + 30
        while not catches_sigterm(proc.pid):
            assert proc.poll() is None and time.monotonic() < deadline, f"{cmd} never handled SIGTERM"
            time.sleep(0.001)
        time.sleep(seconds)
        assert proc.poll() is None, f"{cmd} ended before the signal at {seconds} s: {proc.communicate()[1]}"
        proc.send_signal(sig)
        _, stderr = proc.communicate(timeout=120)
    finally:
        kill_if_running(proc)
    return proc.returncode, stderr


def assert_one_line(app: str, status: int, stderr: str, sig: int, when: str) -> None:
    """Exit status 130 / 143, no traceback, and one line of ``app`` that says it was interrupted."""
    expected, name = SIGNALS[sig]
    assert "Traceback" not in stderr and "Error" not in stderr.replace("error:", ""), f"{when}:\n{stderr}"
    # Python ends a process by SIGINT itself, whatever its exit status, once a KeyboardInterrupt has passed through
    # code it ran with PyRun_* (an extension's initialisation does), as POSIX asks of a program that Ctrl-C stops:
    # a shell reports 130 either way.
    assert status == expected or (sig == signal.SIGINT and status == -signal.SIGINT), f"{when}: status {status}"
    lines = [line for line in stderr.replace("\r", "\n").splitlines() if line.strip()]
    own = [line for line in lines if line.startswith(app) and not PROGRESS_BAR.search(line)]
    assert len(own) == 1 and own[0].startswith(f"{app}: interrupted ({name})"), f"{when}:\n{stderr}"


@pytest.fixture
def busy():
    """A process that keeps one core busy, as another job on the machine does: the imports take longer."""
    proc = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    yield
    proc.kill()
    proc.wait()


def signals_through_start_up(app: str, form: str, inputs, tmp_path) -> None:
    for k, seconds in enumerate(MOMENTS):
        sig = (signal.SIGINT, signal.SIGTERM)[k % 2]
        out = tmp_path / f"{k}"
        out.mkdir()
        cmd = [*command_line(app, form), *command_args(app, inputs, out)]
        status, stderr = signal_after(cmd, seconds, sig, cwd=out)
        assert_one_line(app, status, stderr, sig, f"{form} {app}, {signal.Signals(sig).name} at {seconds} s")


def test_every_console_script_is_faulted(inputs, tmp_path):
    """Every console script of the package has its arguments here, so the fault tests run it."""
    for app in console_scripts():
        assert command_args(app, inputs, tmp_path)


@pytest.mark.integration
@pytest.mark.parametrize("form", ["script", "module"])
@pytest.mark.parametrize("app", console_scripts())
def test_a_signal_at_any_moment_of_the_start_up_ends_in_one_line(app, form, inputs, tmp_path):
    signals_through_start_up(app, form, inputs, tmp_path)


@pytest.mark.integration
@pytest.mark.parametrize("app", console_scripts())
def test_a_signal_during_a_start_up_slowed_by_another_job_ends_in_one_line(app, inputs, tmp_path, busy):
    signals_through_start_up(app, "script", inputs, tmp_path)


def run_command_in_child(body: str, tmp_path: Path, argv=("vical-sim-demo",)) -> subprocess.CompletedProcess:
    """``body`` (the source of a function ``command``) run as the command ``vical-sim-demo`` by ``entry.run`` in a
    child whose working directory (on its module path) is ``tmp_path``: its status, stdout and stderr."""
    code = (
        "import os, signal, sys, threading, time\n"
        f"sys.argv = {list(argv)!r}\n"
        "sys.path.insert(0, '.')\n"
        "import vical.apps.entry as entry\n"
        f"{body}\n"
        "entry.run('vical-sim-demo', command)\n"
    )
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=tmp_path,
                          preexec_fn=default_sigint)  # fmt: skip


@pytest.mark.parametrize("sig", list(SIGNALS))
def test_an_interrupt_that_an_import_turned_into_its_error_ends_the_command_as_the_interrupt(sig, tmp_path):
    """GTSAM's initialisation, interrupted, raises ``ImportError: initialization failed`` from the interrupt: the
    command ends as interrupted (130 / 143, one line), not with the ImportError."""
    interrupt = "entry.Terminated" if sig == signal.SIGTERM else "KeyboardInterrupt"
    body = (
        "def command():\n"
        "    try:\n"
        f"        raise {interrupt}()\n"
        "    except KeyboardInterrupt as err:\n"
        "        raise ImportError('initialization failed') from err\n"
    )
    done = run_command_in_child(body, tmp_path)
    status, name = SIGNALS[sig]
    assert done.returncode == status, done.stderr
    assert done.stderr.strip() == f"vical-sim-demo: interrupted ({name}); nothing was written"


def write_module(folder: Path, name: str, body: str) -> None:
    (folder / f"{name}.py").write_text(body)


@pytest.mark.parametrize("sig", list(SIGNALS))
def test_an_interrupt_during_an_import_waits_for_its_end_and_no_except_around_the_import_swallows_it(sig, tmp_path):
    """A library imports an optional module inside ``except Exception`` (matplotlib its 3D axes): an interrupt that
    lands inside that import (in an extension's initialisation it becomes an ``ImportError``) waits for the import's
    end and is raised at its statement, so the command stops as interrupted, not with status 0."""
    write_module(tmp_path, "optional", f"import os, time\nos.kill(os.getpid(), {int(sig)})\ntime.sleep(0.2)\n"
                                       "import json\nprint('imported whole', flush=True)\n")  # fmt: skip
    body = (
        "def command():\n"
        "    try:\n"
        "        import optional\n"
        "    except Exception:\n"
        "        print('swallowed')\n"
        "    print('went on')\n"
        "    return 0\n"
    )
    done = run_command_in_child(body, tmp_path)
    status, name = SIGNALS[sig]
    assert done.stdout.split("\n") == ["imported whole", ""], done.stderr
    assert (
        done.returncode == status
        and done.stderr.strip() == f"vical-sim-demo: interrupted ({name}); nothing was written"
    )


def test_a_second_interrupt_during_an_import_stops_it_at_once(tmp_path):
    """An import that hangs can still be stopped: the second Ctrl-C raises inside it."""
    ctrl_c = "os.kill(os.getpid(), signal.SIGINT)\n"
    write_module(
        tmp_path,
        "hangs",
        f"import os, signal, time\n{ctrl_c}time.sleep(0.1)\n{ctrl_c}time.sleep(30)\nprint('imported')\n",
    )
    done = run_command_in_child("def command():\n    import hangs\n", tmp_path)
    assert done.returncode == 130 and done.stdout == "", done.stderr
    assert done.stderr.strip() == "vical-sim-demo: interrupted (Ctrl-C); nothing was written"


def test_an_import_in_another_thread_does_not_hold_the_main_threads_interrupt(tmp_path):
    """Only the main thread's imports hold an interrupt: a writer thread importing meanwhile does not delay it."""
    write_module(tmp_path, "slow", "import time\ntime.sleep(20)\n")
    body = (
        "def command():\n"
        "    threading.Thread(target=lambda: __import__('slow'), daemon=True).start()\n"
        "    time.sleep(0.3)\n"
        "    os.kill(os.getpid(), signal.SIGTERM)\n"
        "    time.sleep(20)\n"
    )
    began = time.monotonic()
    done = run_command_in_child(body, tmp_path)
    assert done.returncode == 143 and time.monotonic() - began < 10, done.stderr
    assert done.stderr.strip() == "vical-sim-demo: interrupted (SIGTERM); nothing was written"


def test_the_command_leaves_the_import_statement_as_it_found_it(tmp_path):
    body = "import builtins\nfound = builtins.__import__\ndef command():\n    return 0\n"
    code = body.replace("def command", "import atexit\natexit.register(lambda: print(builtins.__import__ is found))\n"
                                       "def command")  # fmt: skip
    done = run_command_in_child(code, tmp_path)
    assert done.returncode == 0 and done.stdout.strip() == "True", done.stderr


# The command imports matplotlib, then works on (a sleep) until the signal: a signal after a quick import still lands
# in the command, not in the interpreter's exit after it (where the signal's default action is the status, -2/-15).
MATPLOTLIB_IMPORT = (
    "import time\ndef command():\n    print('importing', flush=True)\n    from matplotlib.figure import Figure\n"
    "    time.sleep(60)\n"
)


@pytest.mark.integration
def test_a_signal_at_random_moments_of_a_real_extensions_import_ends_in_one_line(tmp_path):
    """matplotlib's import (pybind11 extensions: ``ft2font`` became ``ImportError: initialization failed``, and the
    interpreter then aborted at its end with status -6; its 3D axes' optional import swallowed the interrupt, status
    0): a real signal at 24 uniform moments of its first 0.5 s (the import takes ~0.27 s on 2 idle cores, more
    under load), each ends in the interrupt's status and one line."""
    rng = np.random.default_rng(40000)
    script = tmp_path / "command.py"
    script.write_text(
        "import sys\nsys.argv = ['vical-sim-demo']\nimport vical.apps.entry as entry\n"
        f"{MATPLOTLIB_IMPORT}\nentry.run('vical-sim-demo', command)\n"
    )
    for k, seconds in enumerate(rng.uniform(0.0, 0.5, 24)):
        sig = (signal.SIGINT, signal.SIGTERM)[k % 2]
        proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True, preexec_fn=default_sigint)  # fmt: skip
        try:
            assert proc.stdout.readline() == "importing\n"
            time.sleep(seconds)
            proc.send_signal(sig)
            _, stderr = proc.communicate(timeout=60)
        finally:
            kill_if_running(proc)
        status, name = SIGNALS[sig]
        when = f"{signal.Signals(sig).name} {seconds:.3f} s into the import"
        assert proc.returncode == status, f"{when}: status {proc.returncode}\n{stderr}"
        assert stderr.strip() == f"vical-sim-demo: interrupted ({name}); nothing was written", f"{when}:\n{stderr}"


def test_an_error_not_caused_by_an_interrupt_is_raised_as_it_is():
    import vical.apps.entry as entry

    def fails():
        raise ImportError("no module named nothing")

    with pytest.raises(ImportError, match="no module named nothing"):
        entry.run("vical-sim-demo", fails)


def test_the_start_up_handling_is_set_for_a_module_run_with_python_minus_m_and_given_back():
    """``python -m vical.apps.<command>``: the package sets the start-up handling before the module's imports (while
    Python finds the module, ``sys.argv[0]`` is ``-m``); the module's ``run`` leaves Python's own handlers behind."""
    code = (
        "import signal, sys\n"
        "sys.argv[0] = '-m'\n"
        "sys.orig_argv = [sys.executable, '-m', 'vical.apps.sim_demo']\n"
        "import vical.apps\n"
        "print(getattr(signal.getsignal(signal.SIGTERM), 'start_up', False))\n"
        "import vical.apps.entry as entry\n"
        "try:\n"
        "    entry.run('vical-sim-demo', lambda: 0)\n"
        "except SystemExit:\n"
        "    print(signal.getsignal(signal.SIGTERM) is signal.SIG_DFL)\n"
        "    print(signal.getsignal(signal.SIGINT) is signal.default_int_handler)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.stdout.split() == ["True", "True", "True"], done.stderr


@pytest.mark.parametrize("sig", list(SIGNALS))
def test_a_signal_during_the_start_up_ends_at_once_with_the_line_and_the_status(sig):
    """The start-up's handler, with a real signal in a child: its line and 130 / 143, whatever the import does."""
    code = (
        "import os, signal, sys, time\n"
        "sys.argv = ['vical-export', 'rec', '--out', 'out']\n"
        "from vical.apps.entry import during_start_up\n"
        "during_start_up('vical-export')\n"
        f"os.kill(os.getpid(), {int(sig)})\n"
        "time.sleep(5)\n"
        "print('not reached')\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                          preexec_fn=default_sigint)  # fmt: skip
    status, name = SIGNALS[sig]
    assert done.returncode == status and done.stdout == ""
    assert done.stderr.strip() == (
        f"vical-export: interrupted ({name}); --out out is as it was: the outputs are written whole or not at all"
    )


@pytest.mark.parametrize("sig", list(SIGNALS))
def test_an_interrupt_while_hydra_starts_is_held_and_raised_as_the_tasks_own_when_it_begins(sig):
    """OmegaConf turns an interrupt landing inside it into its own error (Hydra then exits 1 in several lines): from
    a Hydra app's start until its task begins, Ctrl-C and SIGTERM wait, and the task's first step raises them."""
    code = (
        "import os, signal, sys\n"
        "from vical.apps.entry import _terminate\n"
        "from vical.apps.cli import hydra_start_up_held, task_begins\n"
        "signal.signal(signal.SIGTERM, _terminate)\n"
        "with hydra_start_up_held():\n"
        f"    os.kill(os.getpid(), {int(sig)})\n"
        "    print('held', flush=True)\n"
        "    try:\n"
        "        task_begins()\n"
        "    except KeyboardInterrupt as err:\n"
        "        print('raised', type(err).__name__, flush=True)\n"
        "    print('once', flush=True)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                          preexec_fn=default_sigint)  # fmt: skip
    raised = "Terminated" if sig == signal.SIGTERM else "KeyboardInterrupt"
    assert done.stdout.split("\n")[:3] == ["held", f"raised {raised}", "once"], done.stderr


def test_a_job_started_with_ctrl_c_ignored_keeps_it_ignored_through_the_start_up():
    code = (
        "import signal, sys\n"
        "from vical.apps.entry import during_start_up\n"
        "during_start_up('vical-export')\n"
        "print(signal.getsignal(signal.SIGINT) is signal.SIG_IGN)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                          preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))  # fmt: skip
    assert done.stdout.strip() == "True", done.stderr


# --- A full disk and a read-only folder: each command's output on a small file system of its own -------------------

# Where each command writes (under the folder command_args is given), and the flag that replaces an earlier output.
OUTPUTS = {"vical-calibrate": ("calibration", "--overwrite"), "vical-imu-noise": ("noise", "--overwrite"),
           "vical-record": ("recording", "overwrite=true"), "vical-export": ("export", "--overwrite"),
           "vical-evaluate": ("evaluation", "overwrite=true"), "vical-train": ("run", "overwrite=true"),
           "vical-collect": ("collection", "overwrite=true"), "vical-guide": ("guide", "overwrite=true"),
           "vical-target": ("target", "--overwrite")}  # fmt: skip
# An earlier output, to be kept as it was: a file each command replaces (evaluate's results, a run's config) and one
# it knows nothing of.
PREVIOUS = {"previous.txt": "an earlier output\n", "results.csv": "earlier results\n", "config.yaml": "seed: 1\n"}
# The disk's free space when the command starts: none at all, and one page (one small file fits: the evaluation's
# table, a collection's target.yaml, a run's config).
FREE = {"full": 0, "nearly full": 4096}
# A fault while vical-collect and vical-guide record is the collection's (status 1: the arm is stopped, the recording
# so far kept whole); before, or after it, a user's output error (2), as in every other command.
FAULT_STATUS = {"vical-collect": {1, 2}, "vical-guide": {1, 2}}


def _mounts_a_file_system(prefix: list[str], where: Path) -> bool:
    try:
        done = subprocess.run([*prefix, "sh", "-c", f"mount -t tmpfs -o size=64k tmpfs {where}"], capture_output=True,
                              timeout=30)  # fmt: skip
    except (OSError, subprocess.TimeoutExpired):
        return False
    return done.returncode == 0


def mount_namespace(where: Path) -> list[str] | None:
    """How to run a command with a file system mounted that only it sees: a user and mount namespace of its own (no
    root needed where the kernel allows it), else a mount namespace with sudo; None where neither mounts one."""
    for prefix in (["unshare", "--user", "--map-root-user", "--mount"], ["sudo", "-n", "-E", "unshare", "--mount"]):
        if _mounts_a_file_system(prefix, where):
            return prefix
    return None


@pytest.fixture(scope="module")
def own_mounts(tmp_path_factory) -> list[str]:
    """``mount_namespace``'s prefix; the tests skip, saying why, where there is none."""
    prefix = mount_namespace(tmp_path_factory.mktemp("probe"))
    if prefix is None:
        pytest.skip("no file system can be mounted here (neither unshare --user --mount nor sudo unshare --mount "
                    "works): the full-disk and read-only tests need one")  # fmt: skip
    return prefix


def run_on_own_file_system(
    prefix: list[str], cmd: list[str], folder: Path, free: int | None, seen: Path
) -> tuple[int, str]:
    """Run ``cmd`` in ``folder``, a fresh tmpfs that holds what ``folder`` held, either full but for ``free`` bytes or
    read-only (None); what it holds after the command is copied to ``seen``. The command's status and stderr."""
    if free is None:
        fault_it = f"mount -o remount,ro {folder}"
    else:
        filler = folder / ".filler"
        fault_it = f"dd if=/dev/zero of={filler} bs=4096 2>/dev/null || true; truncate -s -{free} {filler}"
    script = "; ".join([
        f"set -e; cp -a {folder} {seen}.given; mount -t tmpfs -o size=8m tmpfs {folder}",
        f"cp -a {seen}.given/. {folder}", fault_it,
        f'cd {folder}; set +e; timeout 120 "$@"; echo $? > {seen}.status; cd /',
        f"rm -f {folder}/.filler 2>/dev/null; mkdir -p {seen}; cp -a {folder}/. {seen}; chmod -R a+rwX {seen}",
    ])  # fmt: skip
    done = subprocess.run([*prefix, "sh", "-c", script, "sh", *cmd], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                          text=True, timeout=180)  # fmt: skip
    assert done.returncode == 0, done.stderr
    return int(Path(f"{seen}.status").read_text()), done.stderr


def held(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.integration
@pytest.mark.parametrize("fault", [*FREE, "read-only"])
@pytest.mark.parametrize("app", sorted(OUTPUTS))
def test_a_full_disk_or_a_read_only_folder_ends_the_command_in_one_line_keeping_the_earlier_output(
    app, fault, inputs, tmp_path, own_mounts
):
    folder = tmp_path / "disk"
    name, overwrite = OUTPUTS[app]
    (folder / name).mkdir(parents=True)
    for file, text in PREVIOUS.items():
        (folder / name / file).write_text(text)
    earlier = held(folder / name)
    cmd = [str(BIN / app), *command_args(app, inputs, folder), overwrite]
    status, stderr = run_on_own_file_system(own_mounts, cmd, folder, FREE.get(fault), tmp_path / "seen")
    lines = [line for line in stderr.replace("\r", "\n").splitlines() if line.strip() and not PROGRESS_BAR.search(line)]
    assert "Traceback" not in stderr and status in FAULT_STATUS.get(app, {2}), f"{fault}: status {status}\n{stderr}"
    own = [line for line in lines if line.startswith(f"{app}: error:")]
    assert len(own) == 1 and len(lines) == len([ln for ln in lines if ln.startswith(app)]), stderr
    reason = "read-only file system" if fault == "read-only" else "no space left on device"
    assert str(folder / name) in own[0] and (reason in own[0].lower() or "not writable" in own[0]), own[0]
    seen = tmp_path / "seen"
    assert held(seen / name) == earlier, "the earlier output changed"
    assert not [p for p in seen.rglob("*") if ".tmp-" in p.name], "a temporary file was left"


@pytest.mark.integration
@pytest.mark.parametrize("mode", [["images=false"], ["mode=static_imu"]], ids=["without images", "static IMU"])
def test_a_full_disk_ends_every_kind_of_recording_in_one_line(mode, tmp_path, own_mounts):
    """vical-record's other writers (the recording without images, the resting IMU's) on a disk with one page free."""
    folder = tmp_path / "disk"
    folder.mkdir()
    cmd = [str(BIN / "vical-record"), f"out={folder / 'recording'}", *mode]
    status, stderr = run_on_own_file_system(own_mounts, cmd, folder, FREE["nearly full"], tmp_path / "seen")
    lines = [line for line in stderr.replace("\r", "\n").splitlines() if line.startswith("vical-record: error:")]
    assert status == 2 and "Traceback" not in stderr and len(lines) == 1, stderr
    assert lines[0].startswith(f"vical-record: error: out={folder / 'recording'}: cannot write it (no space left on")
    assert not (tmp_path / "seen" / "recording").exists()


@pytest.mark.integration
def test_a_disk_that_fills_while_the_guide_records_stops_it_in_one_line_with_the_recording_so_far_whole(
    tmp_path, own_mounts
):
    """A real full disk (ENOSPC on a tmpfs with 1 MiB free) a few frames into the guidance: status 1, one line saying
    the disk took no more and where the recording is; what it holds reads back whole."""
    folder = tmp_path / "disk"
    folder.mkdir()
    cmd = [str(BIN / "vical-guide"), f"out={folder / 'guide'}", "page.enabled=false", "report=false", "seed=3"]
    status, stderr = run_on_own_file_system(own_mounts, cmd, folder, 1 << 20, tmp_path / "seen")
    (line,) = [line for line in stderr.splitlines() if line.startswith("vical-guide")]
    assert status == 1 and "Traceback" not in stderr, stderr
    recording = folder / "guide" / "recording"
    assert line.startswith(f"vical-guide: error: stopped: {recording}: the disk took no more (")
    assert "No space left on device; is it full?)" in line and f"the recording so far is in {recording}" in line
    seen = tmp_path / "seen" / "guide"
    frames = read_euroc(seen / "recording", read_target_yaml(seen / "target.yaml")).frames
    assert 0 < len(frames) == len(frames.images)


@pytest.mark.integration
def test_the_demo_writes_nothing_so_a_read_only_folder_changes_nothing(inputs, tmp_path, own_mounts):
    folder = tmp_path / "disk"
    folder.mkdir()
    cmd = [str(BIN / "vical-sim-demo"), *command_args("vical-sim-demo", inputs, folder)]
    status, stderr = run_on_own_file_system(own_mounts, cmd, folder, None, tmp_path / "seen")
    assert status == 0 and "Traceback" not in stderr and held(tmp_path / "seen") == {}, stderr


def test_every_writing_command_is_faulted_on_a_full_disk():
    """Every console script but the demo (which writes nothing: tested above) is run on a full and a read-only disk."""
    assert set(OUTPUTS) == set(console_scripts()) - {"vical-sim-demo"}
