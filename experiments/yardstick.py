"""The yardstick: run ``+experiment=yardstick_<task>`` for the joint and intrinsic tasks, keep the results.

Runs ``vical-evaluate`` for each task (50 sensors, seeds 10000..10049, every baseline, budgets
0.5-8 m), writes ``evaluations/yardstick_<task>/`` (results.csv, summary.md, error_vs_effort.png),
copies each figure to ``docs/figures/yardstick_<task>.png`` and prints the fingerprint of the
yardstick (``vical.evaluation.yardstick``) that docs/results.md records. Fixed seeds: running it
again gives the same numbers, as long as the calibrator and the simulator are unchanged.

Usage:
    python experiments/yardstick.py                     # both tasks, about 1.5 h on 2 cores
    python experiments/yardstick.py --tasks intrinsic   # one task
    python experiments/yardstick.py --fingerprint       # only print the fingerprint
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import time
from pathlib import Path

from vical.apps.evaluate import FIGURE, yardstick_fingerprint

ROOT = Path(__file__).resolve().parents[1]
TASKS = ("joint", "intrinsic")


def run(task: str, out: Path) -> None:
    """``vical-evaluate +experiment=yardstick_<task>`` into ``out`` (replaced), with its progress bars."""
    command = [sys.executable, "-m", "vical.apps.evaluate", f"+experiment=yardstick_{task}", f"out={out}"]
    start = time.perf_counter()
    subprocess.run([*command, "overwrite=true"], cwd=ROOT, check=True)
    print(f"== yardstick_{task}: {time.perf_counter() - start:.0f} s; results in {out}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", nargs="+", choices=TASKS, default=list(TASKS))
    parser.add_argument("--out", type=Path, default=ROOT / "evaluations", help="parent of yardstick_<task>/")
    parser.add_argument("--fingerprint", action="store_true", help="only print the fingerprint")
    args = parser.parse_args()
    if not args.fingerprint:
        for task in args.tasks:
            out = args.out / f"yardstick_{task}"
            run(task, out)
            figures = ROOT / "docs" / "figures"
            figures.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(out / FIGURE, figures / f"yardstick_{task}.png")
    for task in TASKS:
        print(f"fingerprint of yardstick_{task}:")
        for part, digest in yardstick_fingerprint(task).items():
            print(f"  {part}: {digest}")


if __name__ == "__main__":
    main()
