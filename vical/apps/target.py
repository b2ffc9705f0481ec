"""``vical-target``: a calibration target to print, at true scale, with its Kalibr target YAML.

Examples::

    vical-target --out board --kind aprilgrid --rows 6 --cols 6 --size 0.088 --spacing 0.3 --paper A0
    vical-target --out small --rows 4 --cols 5 --size 0.03 --spacing 0.25     # fits A4
    vical-target --out board --target my_target.yaml --paper A3

Writes into ``--out``: ``target.pdf`` (vector, the board centred on the paper at its true size: print it at
100 %, without "fit to page"), ``target.png`` (the same sheet at ``--dpi``) and ``target.yaml`` (Kalibr's target
file of the printed board), together (``vical.io.atomic.files_together``). It prints what to measure on the print
with a ruler. A board that does not fit the paper is refused before anything is written, naming the smallest
paper that holds it (``vical.io.printable_target``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from vical.apps.cli import ArgumentParser, argparse_main
from vical.apps.entry import run as run_command
from vical.data import Target, TargetError
from vical.io.atomic import files_together, remove_stale_temporaries
from vical.io.errors import FormatError
from vical.io.kalibr import read_target_yaml, write_target_yaml
from vical.io.printable_target import PAPERS, check_lengths, sheet_layout, write_sheet

APP = "vical-target"
FILES = ("target.pdf", "target.png", "target.yaml")


class TargetOutputError(FileExistsError):
    """An ``--out`` that holds another target, without ``--overwrite``."""


def build_parser() -> ArgumentParser:
    p = ArgumentParser(prog=APP, description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output directory (its target files replaced only with --overwrite)")
    p.add_argument("--target", help="a Kalibr target YAML to print (instead of --kind and its sizes)")
    p.add_argument("--kind", choices=("aprilgrid", "checkerboard"), default="aprilgrid")
    p.add_argument("--rows", type=int, default=6, help="aprilgrid: tag rows; checkerboard: inner corner rows")
    p.add_argument("--cols", type=int, default=6, help="aprilgrid: tag columns; checkerboard: inner corner columns")
    p.add_argument(
        "--size",
        type=float,
        help="[m] aprilgrid: tag side; checkerboard: square side (Kalibr's tagSize, rowSpacingMeters)",
    )
    p.add_argument("--spacing", type=float, default=0.3, help="aprilgrid: gap between tags / tag side")
    p.add_argument("--paper", default="A4", choices=tuple(PAPERS), help="paper size (default A4)")
    p.add_argument("--dpi", type=int, default=300, help="the PNG's resolution (default 300)")
    p.add_argument("--overwrite", action="store_true", help="replace the target files --out holds")
    return p


def target_of(args: argparse.Namespace) -> Target:
    if args.target is not None:
        return read_target_yaml(args.target)
    if args.size is None:
        raise TargetError(
            "give the board with --size [m] (its tag's or square's side) or --target <Kalibr target YAML>"
        )
    if args.kind == "aprilgrid":
        return Target("aprilgrid", args.rows, args.cols, args.size, args.size, args.spacing)
    return Target("checkerboard", args.rows, args.cols, args.size, args.size)


def check_out(out: Path, overwrite: bool) -> None:
    if out.exists() and not out.is_dir():
        raise TargetOutputError(f"--out {out} is a file; give a directory")
    remove_stale_temporaries(out)
    held = [name for name in FILES if (out / name).exists()]
    if held and not overwrite:
        raise TargetOutputError(f"--out {out} holds {', '.join(held)}; choose another directory or pass --overwrite")


def run(args: argparse.Namespace) -> None:
    if not 30 <= args.dpi <= 1200:
        raise TargetError(f"--dpi {args.dpi}: give a resolution from 30 to 1200")
    out = Path(args.out)
    check_out(out, args.overwrite)
    target = target_of(args)
    sheet = sheet_layout(target, args.paper)  # before anything is written: a board too big for the paper
    with files_together(out) as path_of:
        write_sheet(sheet, path_of("target.pdf"), path_of("target.png"), args.dpi)
        write_target_yaml(path_of("target.yaml"), target)
    turned = " (landscape)" if sheet.paper[0] > sheet.paper[1] else ""
    print(f"target written to {out}: target.pdf ({args.paper}{turned}; print at 100 %, not 'fit to page'), "
          f"target.png ({args.dpi} dpi), target.yaml (Kalibr)")  # fmt: skip
    print(f"check with a ruler: {check_lengths(target)}")


def main(argv: list[str] | None = None) -> int:
    """Console entry point; returns the exit status (0 ok, 2 bad input)."""
    errors = (TargetError, FormatError, TargetOutputError)
    return argparse_main(APP, build_parser(), run, errors, {}, argv)


if __name__ == "__main__":  # python -m: the console script's handling of Ctrl-C and SIGTERM
    run_command(APP, main)
