"""Faults at random moments in every command: how many end in one line with their exit status, and how many do not.

Each case draws a command (every console script), a fault and its moment: SIGINT or SIGTERM at a uniform time in
the first ``--within`` seconds after the process starts (as a supervisor sends it: the interpreter's own start-up
included), a disk with ``--free`` bytes left (one drawn) or a read-only one under the command's output (a tmpfs in
a mount namespace of the case's own, as in ``tests/test_faults.py``, whose commands and arguments it runs). A case
is right when its stderr holds no traceback, exactly one line of the command's own, and the status is 130 / 143
(a signal; Python's own -SIGINT counts as 130) or 2 (a disk; 1 for a collection's recording). A signal sent before
the process handles SIGTERM (the interpreter's first ~50 ms, before any of vical runs) is counted apart, as is one
sent once the command's work was done and its handling given back (``after its work``: its outputs are whole), and
a command that ended before its signal. Two cases run at once (the machine busy, as under a supervisor).

    .venv/bin/python experiments/fault_audit.py --cases 460 --seed 40000
"""

from __future__ import annotations

import argparse
import collections
import random
import signal
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import test_faults as faults  # noqa: E402  (the fault tests' commands, arguments and file systems)

SIGNAL_STATUS = {"SIGINT": 130, "SIGTERM": 143}


@dataclass(frozen=True)
class Case:
    app: str
    fault: str  # SIGINT, SIGTERM, full disk, read-only
    moment: float  # [s] after the start (a signal), or the bytes left (a full disk)


@dataclass(frozen=True)
class Outcome:
    case: Case
    verdict: str  # right, traceback, wrong status, not one line, before vical ran, after its work, ended before
    status: int
    stderr: str


class _Inputs:
    """``tmp_path_factory`` for the fault tests' ``inputs`` fixture."""

    def __init__(self, root: Path) -> None:
        self.root = root

    def mktemp(self, name: str) -> Path:
        path = self.root / name
        path.mkdir()
        return path


def draw_cases(n: int, seed: int, within: float, free: list[int]) -> list[Case]:
    rng = random.Random(seed)
    apps = faults.console_scripts()
    cases = []
    for _ in range(n):
        app = rng.choice(apps)
        kinds = ["SIGINT", "SIGTERM"] + (["full disk", "read-only"] if app in faults.OUTPUTS else [])
        fault = rng.choice(kinds)
        moment = rng.uniform(0.0, within) if fault in SIGNAL_STATUS else float(rng.choice(free))
        cases.append(Case(app, fault, moment))
    return cases


def judge(app: str, stderr: str, status: int, expected: set[int]) -> str:
    if "Traceback" in stderr:
        return "traceback"
    if status not in expected:
        return "wrong status"
    lines = [line for line in stderr.replace("\r", "\n").splitlines() if line.strip()]
    own = [line for line in lines if line.startswith(app) and not faults.PROGRESS_BAR.search(line)]
    return "right" if len(own) == 1 else "not one line"


def run_signal(case: Case, inputs: dict[str, Path], work: Path) -> Outcome:
    cmd = [*faults.command_line(case.app, "script"), *faults.command_args(case.app, inputs, work)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=work,
                            preexec_fn=faults.default_sigint)  # fmt: skip
    try:
        handled_once, start = False, time.monotonic()
        while time.monotonic() - start < case.moment and proc.poll() is None:
            handled_once = handled_once or faults.catches_sigterm(proc.pid)
            time.sleep(0.002)
        if proc.poll() is not None:
            return Outcome(case, "ended before the signal", proc.returncode, proc.communicate()[1])
        handled = faults.catches_sigterm(proc.pid)
        sig = getattr(signal, case.fault)
        proc.send_signal(sig)
        _, stderr = proc.communicate(timeout=120)
    finally:
        faults.kill_if_running(proc)
    expected = {SIGNAL_STATUS[case.fault]} | ({-signal.SIGINT} if case.fault == "SIGINT" else set())
    verdict = judge(case.app, stderr, proc.returncode, expected)
    if verdict != "right" and not handled:  # vical's handling not yet in place, or given back once the work was done
        verdict = "after its work" if handled_once else "before vical ran"
    return Outcome(case, verdict, proc.returncode, stderr)


def run_disk(case: Case, inputs: dict[str, Path], work: Path, mounts: list[str]) -> Outcome:
    name, overwrite = faults.OUTPUTS[case.app]
    folder = work / "disk"
    (folder / name).mkdir(parents=True)
    (folder / name / "previous.txt").write_text("an earlier output\n")
    cmd = [*faults.command_line(case.app, "script"), *faults.command_args(case.app, inputs, folder), overwrite]
    free = None if case.fault == "read-only" else int(case.moment)
    status, stderr = faults.run_on_own_file_system(mounts, cmd, folder, free, work / "seen")
    if status == 0:  # the output fitted in what was left
        return Outcome(case, "fitted", status, stderr)
    return Outcome(case, judge(case.app, stderr, status, faults.FAULT_STATUS.get(case.app, {2})), status, stderr)


def table(outcomes: list[Outcome]) -> str:
    verdicts = ["right", "traceback", "wrong status", "not one line", "before vical ran", "after its work",
                "ended before the signal", "fitted"]  # fmt: skip
    counts = collections.Counter((o.case.app, o.case.fault, o.verdict) for o in outcomes)
    keys = sorted({(o.case.app, o.case.fault) for o in outcomes})
    rows = ["| command | fault | cases | " + " | ".join(verdicts) + " |", "|---|---|---:|" + "---:|" * len(verdicts)]
    for app, fault in keys:
        n = sum(counts[(app, fault, v)] for v in verdicts)
        rows.append(f"| {app} | {fault} | {n} | " + " | ".join(str(counts[(app, fault, v)]) for v in verdicts) + " |")
    total = collections.Counter(o.verdict for o in outcomes)
    rows.append(f"| all | | {len(outcomes)} | " + " | ".join(str(total[v]) for v in verdicts) + " |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=460)
    parser.add_argument("--seed", type=int, default=40000)
    parser.add_argument("--within", type=float, default=2.5, help="signals at a uniform time in [0, within] s")
    parser.add_argument("--free", type=int, nargs="+", default=[0, 4096, 65536, 1 << 20], help="bytes left")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args(argv)
    root = Path(tempfile.mkdtemp(prefix="vical-fault-audit-"))
    (root / "inputs-root").mkdir()
    inputs = faults.inputs.__wrapped__(_Inputs(root / "inputs-root"))
    mounts = faults.mount_namespace(root / "inputs-root")
    cases = draw_cases(args.cases, args.seed, args.within, args.free)
    if mounts is None:
        print("no file system can be mounted here: the disk cases are left out", file=sys.stderr)
        cases = [c for c in cases if c.fault in SIGNAL_STATUS]

    def run(k_case: tuple[int, Case]) -> Outcome:
        k, case = k_case
        work = root / f"case{k}"
        work.mkdir()
        if case.fault in SIGNAL_STATUS:
            return run_signal(case, inputs, work)
        return run_disk(case, inputs, work, mounts)

    outcomes = []
    with ThreadPoolExecutor(args.jobs) as pool:
        for k, outcome in enumerate(pool.map(run, enumerate(cases)), 1):
            outcomes.append(outcome)
            if outcome.verdict not in ("right", "fitted", "ended before the signal"):
                print(f"case {k}: {outcome.case} -> {outcome.verdict} ({outcome.status}):\n{outcome.stderr[-1500:]}",
                      file=sys.stderr)  # fmt: skip
            print(f"\r{k}/{len(cases)} cases", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    print(table(outcomes))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
