"""The tutorials print what their pages show: every ``$ command`` of docs/tutorial-export-to-kalibr.md,
docs/tutorial-calibrate-your-recording.md and docs/tutorial-guided.md runs (in one working directory, in page order),
and its output is compared with the lines below it on the page.

Comparison: line by line; a page line ``...`` stands for any number of output lines; numbers agree to 1e-6
relative or 1e-9 absolute (the last digits of full-precision floats may differ between machines); solve times are
not compared.
``vical-record`` and ``vical-guide`` run as their console scripts (Hydra), the other apps through their
``main(argv)``; every file a page uses is made by a command on it.
"""

from __future__ import annotations

import contextlib
import io
import math
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from vical.apps import calibrate, export, imu_noise

DOCS = Path(__file__).resolve().parents[1] / "docs"
# The second uses the first's files; the third runs on a simulated person.
PAGES = ("tutorial-export-to-kalibr.md", "tutorial-calibrate-your-recording.md", "tutorial-guided.md")
NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")
# Wall-clock times vary from run to run: "solve time [s]  0.107", "solver: converged, 3 iterations, 0.107 s".
SOLVE_TIME = re.compile(r"(?<=solve time \[s\])\s+[\d.]+|(?<=iterations, )[\d.]+(?= s)")


@dataclass(frozen=True)
class Example:
    """A ``$ command`` on a page and the output lines shown below it."""

    page: str
    command: str
    shown: list[str]


def examples(page: str) -> list[Example]:
    """The ``$ `` commands of the page's code blocks with their shown output, in page order."""
    found = []
    blocks = re.findall(r"^```[^\n]*\n(.*?)^```", (DOCS / page).read_text(), flags=re.MULTILINE | re.DOTALL)
    for block in (b for b in blocks if b.startswith("$ ")):  # other blocks show code, not a session
        for line in block.splitlines():
            if line.startswith("$ "):
                found.append(Example(page, line[2:], []))
            else:
                found[-1].shown.append(line)
    return found


def _in_process(main, argv: list[str], cwd: Path) -> str:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.chdir(cwd), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        main(argv)
    # stderr: the one-line messages, not the progress bars
    messages = [line for line in err.getvalue().replace("\r", "\n").splitlines() if line.startswith("vical-")]
    return out.getvalue() + "".join(f"{m}\n" for m in messages)


def run(command: str, cwd: Path) -> str:
    """What ``command`` prints, run in ``cwd``."""
    program, *argv = shlex.split(command)
    if program in ("vical-record", "vical-guide"):  # Hydra apps: their console scripts
        done = subprocess.run(
            [str(Path(sys.executable).parent / program), *argv], cwd=cwd, capture_output=True, text=True, timeout=300
        )
        assert done.returncode == 0, done.stderr
        return done.stdout
    if program == "cat":
        return (cwd / argv[0]).read_text()
    if program == "ls":
        return "  ".join(sorted(p.name for p in (cwd / argv[0]).iterdir())) + "\n"
    apps = {"vical-calibrate": calibrate.main, "vical-export": export.main, "vical-imu-noise": imu_noise.main}
    assert program in apps, f"the test cannot run {program!r}: run it here or take the $ off the page"
    return _in_process(apps[program], argv, cwd)


def lines_agree(shown: str, printed: str) -> bool:
    """Text equal, numbers equal to 1e-6 relative or 1e-9 absolute.

    The absolute part is for full-precision numbers near zero: a 4.6e-06 s time offset differed by
    6e-11 s (1e-6 of its 1-sigma) between two CPUs.
    """
    shown, printed = SOLVE_TIME.sub(" <time>", shown), SOLVE_TIME.sub(" <time>", printed)
    if NUMBER.sub("#", shown) != NUMBER.sub("#", printed):
        return False
    pairs = zip(NUMBER.findall(shown), NUMBER.findall(printed), strict=True)
    return all(math.isclose(float(a), float(b), rel_tol=1e-6, abs_tol=1e-9) for a, b in pairs)


def matches(shown: list[str], printed: list[str]) -> bool:
    """Whether ``printed`` fits ``shown`` line by line, a shown ``...`` taking any number of lines."""
    if not shown:
        return not printed
    if shown[0] == "...":
        return any(matches(shown[1:], printed[k:]) for k in range(len(printed) + 1))
    return bool(printed) and lines_agree(shown[0], printed[0]) and matches(shown[1:], printed[1:])


@pytest.fixture(scope="module")
def outputs(tmp_path_factory) -> dict[str, list[tuple[Example, list[str]]]]:
    """Every page's examples with what they printed, run in order in one working directory."""
    cwd = tmp_path_factory.mktemp("tutorial")
    return {page: [(e, run(e.command, cwd).splitlines()) for e in examples(page)] for page in PAGES}


@pytest.mark.integration
@pytest.mark.parametrize("page", PAGES)
def test_the_tutorial_prints_what_its_page_shows(outputs, page):
    ran = outputs[page]
    assert len(ran) >= 3
    for example, printed in ran:
        assert matches(example.shown, printed), (
            f"{page}: `{example.command}` printed\n" + "\n".join(printed) + "\nbut the page shows\n"
            + "\n".join(example.shown)
        )  # fmt: skip


def test_the_comparison_sees_a_changed_number_and_skips_solve_times():
    shown = ["fx fy [px]  522.087 522.074", "solve time [s]  0.107   3 iterations, converged", "..."]
    assert matches(shown, ["fx fy [px]  522.087 522.074", "solve time [s]  0.090   3 iterations, converged"])
    assert not matches(shown, ["fx fy [px]  522.087 522.075", "solve time [s]  0.107   3 iterations, converged"])
    assert not matches(shown, ["fx fy [px]  522.087 522.074", "solve time [s]  0.107   4 iterations, converged"])
    assert not matches(["a", "b"], ["a", "b", "c"]) and matches(["a", "...", "c"], ["a", "b", "b", "c"])
