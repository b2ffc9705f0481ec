"""``vical-train``: the Hydra entry point of :func:`vical.rl.trainer.train` (config: ``conf/train.yaml``).

``vical-train resume=<run dir>`` continues a run from its checkpoint with the run's saved config; other
``key=value`` overrides on the command line apply on top (only the length of the run and the cadence of
logging, evaluation and checkpoints may differ from the checkpoint's config: ``RESUMABLE_KEYS``). On
resume, overrides may only change keys the saved config has: group selections (``agent=...``), additions
(``+key=...``) and deletions (``~key``) are refused by name. A finished run resumed at its own length is
complete (nothing to do); with a larger ``train.total_steps`` it goes on (``vical.rl.checkpoint.resume_status``);
with a smaller one it is refused.

User-facing errors (a bad config value, Hydra's own override errors, an incompatible or unreadable
checkpoint, a missing run directory, diverged training, a dead env worker or an env that raised in its
reset, an unreachable Ray cluster) print one line ``vical-train: error: ...`` and exit with status 2, as
``vical-calibrate`` does; they are checked before Hydra creates the run directory where the command line
allows (no ``-m`` or other Hydra flags), env workers start before the run directory is written, and a run
directory that an error left empty is removed. Ctrl-C stops the run with one line saying how to resume it
(exit status 130; SIGTERM 143).

A ``run_dir`` that holds a run is refused unless the run is resumed (``resume=``) or ``overwrite=true``: the new
run then trains in a sibling directory and replaces the old one only once it is complete (an interrupted or
failed new run leaves the old one as it was).
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.core.override_parser.types import Override, OverrideType
from hydra.errors import InstantiationException
from omegaconf import DictConfig, OmegaConf

from vical.apps.cli import (
    OutputError,
    check_composes,
    check_creatable,
    check_launcher,
    fail,
    hydra_start_up_held,
    one_line_warnings,
    override_value,
    quiet_library_logs,
    task_begins,
    write_faults_in_one_line,
)
from vical.apps.entry import interrupted_by, interrupted_status
from vical.apps.entry import run as run_command
from vical.config_checks import ConfigError
from vical.io.atomic import replace_directory, unused_sibling
from vical.parallel import check_ray_address
from vical.rl.checkpoint import (
    AGENT,
    CHECKPOINT,
    IncompatibleCheckpointError,
    UnreadableCheckpointError,
    checkpoint_step,
    resume_status,
)
from vical.rl.demonstrations import make_demonstrator
from vical.rl.run_settings import RunSettings, parse_settings
from vical.rl.single_env_trainer import TrainingDivergedError
from vical.rl.trainer import train
from vical.rl.vector_trainer import EnvWorkerError, WorkerDiedError

# An absolute path: a relative config_path would resolve against the installed package when the console
# script runs from another directory.
CONF_DIR = str(Path(__file__).resolve().parents[2] / "conf")

# Errors whose message tells the user what to fix: printed as one line, no traceback.
USER_ERRORS = (
    ConfigError,
    IncompatibleCheckpointError,
    UnreadableCheckpointError,
    FileNotFoundError,
    TrainingDivergedError,
    WorkerDiedError,
    EnvWorkerError,
    InstantiationException,  # the env's _target_ could not be built (bad id, bad arguments)
    OutputError,
)
APP = "vical-train"

_ABSENT = object()


def _run_dir(resume: str | None, run_dir: str | None, fresh: str) -> str:
    """hydra.run.dir: the run being resumed (so no second output directory appears), the ``run_dir`` asked for
    (so that train.log lands in it), else a fresh one."""
    if resume:
        check_resume_dir(resume)  # never let Hydra create a directory for a mistyped resume path
        return resume
    return run_dir or fresh


OmegaConf.register_new_resolver("vical_run_dir", _run_dir, replace=True)


def check_resume_dir(resume: str) -> Path:
    """``resume`` as a Path; ``ConfigError`` unless it is a run directory of vical-train (holds config.yaml)."""
    path = Path(resume)
    if not (path / "config.yaml").is_file():
        what = "does not exist" if not path.exists() else "has no config.yaml"
        raise ConfigError(f"resume must be a run directory of vical-train containing config.yaml; {resume!r} {what}")
    return path


def resumed_config(resume: str, overrides: list[str]) -> DictConfig:
    """The saved config of the run at ``resume`` with the command line's ``key=value`` overrides applied.

    Only plain ``key=value`` changes of keys present in the saved config are accepted; anything else
    (group selections, ``+``/``++`` additions, ``~`` deletions, unknown keys) raises ``ConfigError`` naming
    each offending override.
    """
    cfg = OmegaConf.load(check_resume_dir(resume) / "config.yaml")
    parsed = [o for o in OverridesParser.create().parse_overrides(overrides) if o.key_or_group != "resume"]
    refused = [f"{o.input_line} ({why})" for o in parsed if (why := _refusal(o, cfg))]
    if refused:
        listing = "\n  ".join(refused)
        raise ConfigError(
            f"on resume the run's saved config ({Path(resume) / 'config.yaml'}) is used; these overrides cannot "
            f"apply to it:\n  {listing}\nOnly key=value changes of existing keys are accepted "
            "(e.g. train.total_steps=20000); start a new run to change anything else."
        )
    for o in parsed:
        OmegaConf.update(cfg, o.key_or_group, o.value(), merge=False)
    cfg.resume = resume
    cfg.run_dir = resume
    return cfg


def _refusal(override: Override, saved: DictConfig) -> str | None:
    """Why ``override`` cannot apply to a resumed run's saved config, or None when it can."""
    key = override.key_or_group
    if override.is_sweep_override():
        return "a sweep"
    if override.type == OverrideType.DEL:
        return "a deletion: the saved config is complete"
    if override.type in (OverrideType.ADD, OverrideType.FORCE_ADD):
        return "an addition: only keys of the saved config may change"
    if override.package is not None or (Path(CONF_DIR) / key).is_dir():
        return f"a config group selection: the saved config already fixes {key}"
    value = OmegaConf.select(saved, key, default=_ABSENT)
    if value is _ABSENT:
        return f"unknown key {key!r}"
    if isinstance(value, DictConfig):
        return f"{key} is a section, set its keys one by one ({key}.<key>=...)"
    return None


def check_command_line(argv: list[str]) -> str | None:
    """Everything about the command line that can be checked before Hydra creates a run directory.

    Returns the message that a resumed run is complete already (nothing to train), else None.
    Raises one of ``USER_ERRORS``.
    """
    check_launcher(argv)
    resume = override_value(argv, "resume")
    if resume is not None:
        check_resume_dir(resume)
    for key in ("run_dir", "hydra.run.dir"):
        value = override_value(argv, key)
        if value is not None and Path(value).exists() and not Path(value).is_dir():
            raise ConfigError(f"{key}={value} is a file; give a directory for the run")
        if value is not None and resume is None:
            check_creatable(f"{key}=", value)  # Hydra makes it (and its train.log) before the run: a traceback there
    if resume is None and not any(override_value(argv, key) for key in ("run_dir", "hydra.run.dir")):
        check_creatable("run_dir=", "runs/<date>_<time>")  # Hydra's default, below the working directory
    cfg = check_composes(CONF_DIR, "train", argv)
    if cfg is None:
        return None  # Hydra flags (-m, --cfg, ...): Hydra and the task function check the rest
    held = held_run(argv) if resume is None else None
    if held is not None and not cfg.overwrite:
        key, path, found = held
        raise ConfigError(
            f"{key}={path} holds a vical-train run ({', '.join(found)}); continue it with resume={path}, choose "
            f"another {key}, or pass overwrite=true to replace it once the new run is complete"
        )
    if resume is not None:
        resumed = resumed_config(resume, argv)
        complete = resume_status(resume, resumed.train.total_steps)
        if complete is None:
            _check_run(parse_settings(OmegaConf.to_container(resumed, resolve=True)))
        return complete
    settings = OmegaConf.to_container(cfg, resolve=True)
    _check_run(parse_settings({**settings, "run_dir": settings["run_dir"] or "runs/<time>"}))  # Hydra names it
    return None


RUN_FILES = ("config.yaml", CHECKPOINT, AGENT)  # what makes a directory hold a run


def held_run(argv: list[str]) -> tuple[str, Path, list[str]] | None:
    """(key, directory, run files) of the ``run_dir`` (or ``hydra.run.dir``) the command line names when it holds a
    run, else None."""
    for key in ("run_dir", "hydra.run.dir"):
        value = override_value(argv, key)
        if value is not None:
            found = [name for name in RUN_FILES if (Path(value) / name).exists()]
            if found:
                return key, Path(value), found
    return None


def train_aside(argv: list[str], key: str, run_dir: Path) -> tuple[list[str], Path]:
    """The command line with ``key`` pointing at a fresh sibling of ``run_dir`` where the new run trains, and that
    sibling."""
    aside = unused_sibling(run_dir, "new")  # Hydra creates it
    return [f"{key}={aside}" if a.lstrip("+").startswith(f"{key}=") else a for a in argv], aside


def _check_run(settings: RunSettings) -> None:
    """What the run needs from outside its config, before the run directory exists: a Ray cluster that answers
    (only env workers use it: train.num_envs > 1; refused within seconds) and a demonstrator that builds."""
    if settings.train.num_envs > 1:
        check_ray_address(settings.parallel)
    make_demonstrator(settings.train.demonstrator)


def _remove_unused(run_dir: Path) -> None:
    """Remove a run directory that holds nothing but Hydra's empty log (the run stopped before it began), and
    the parents below the working directory that it leaves empty."""
    if not run_dir.is_dir() or any(e.suffix != ".log" or e.stat().st_size for e in run_dir.iterdir()):
        return
    shutil.rmtree(run_dir)
    cwd = Path.cwd().resolve()
    for parent in run_dir.resolve().parents:
        if parent == cwd or cwd not in parent.parents or any(parent.iterdir()):
            break
        parent.rmdir()


def _last_checkpoint(run_dir: Path) -> int | None:
    try:
        return checkpoint_step(run_dir)
    except UnreadableCheckpointError:
        return None


def interrupted_message(run_dir: Path, by: str = "Ctrl-C") -> str:
    """Where a run stopped ``by`` Ctrl-C or SIGTERM can go on from, and the command that does it."""
    step = _last_checkpoint(run_dir)
    if step is None:
        return (
            f"{APP}: interrupted ({by}) before the run's first checkpoint; nothing to resume in {run_dir}: start it "
            "again"
        )
    return (
        f"{APP}: interrupted ({by}); the last checkpoint (step {step}) is {run_dir / CHECKPOINT}; "
        f"continue with: {APP} resume={run_dir}"
    )


def kept_when_unwritable(run_dir: Path) -> str:
    """What a run that the disk stopped (full, read-only) keeps: its last whole checkpoint, and how to go on."""
    step = _last_checkpoint(run_dir)
    if step is None:
        return "no checkpoint was written yet"
    return f"its last checkpoint (step {step}) is whole: continue with {APP} resume={run_dir} once there is space"


@hydra.main(config_path=CONF_DIR, config_name="train", version_base="1.3")
def hydra_main(cfg: DictConfig) -> None:
    task_begins()
    output_dir = Path(HydraConfig.get().runtime.output_dir)
    try:
        if cfg.resume:
            cfg = resumed_config(str(cfg.resume), list(HydraConfig.get().overrides.task))
            complete = resume_status(cfg.run_dir, cfg.train.total_steps)
            if complete:
                print(complete)
                return
        elif cfg.run_dir is None:
            cfg.run_dir = str(output_dir)
        run_dir = Path(cfg.run_dir)
        with write_faults_in_one_line(APP, "run_dir=", run_dir, lambda: kept_when_unwritable(run_dir)):
            result = train(cfg)
    except USER_ERRORS as err:
        _remove_unused(output_dir)
        fail(APP, err)
    except KeyboardInterrupt as err:  # Ctrl-C, or SIGTERM (vical.apps.entry)
        print(interrupted_message(Path(cfg.run_dir or output_dir), interrupted_by(err)), file=sys.stderr)
        raise SystemExit(interrupted_status(err)) from None
    print(f"trained {result.steps} steps, {result.episodes} episodes; run directory: {result.run_dir}")


def main() -> None:
    """Console entry point: check the command line before Hydra starts, then run."""
    one_line_warnings()
    quiet_library_logs()
    with hydra_start_up_held():
        _check_then_train()


def _check_then_train() -> None:
    try:
        complete = check_command_line(sys.argv[1:])
    except USER_ERRORS as err:
        fail(APP, err)
    if complete:
        print(complete)
        return
    argv = sys.argv[1:]
    hydra_flags = any(a.startswith("-") for a in argv)  # -m and the like: Hydra names the run directories
    held = None if hydra_flags or override_value(argv, "resume") else held_run(argv)
    if held is not None:  # overwrite=true (check_command_line refused it otherwise): train beside the old run
        key, run_dir, _ = held
        sys.argv[1:], aside = train_aside(argv, key, run_dir)
    try:
        hydra_main()
    except KeyboardInterrupt as err:  # before the run began (Hydra starting, the env being built)
        print(f"{APP}: interrupted ({interrupted_by(err)}) before the run began", file=sys.stderr)
        raise SystemExit(interrupted_status(err)) from None
    if held is not None:
        replace_directory(aside, run_dir)
        print(f"replaced the run in {run_dir} by the new one")


if __name__ == "__main__":  # python -m: the console script's handling of Ctrl-C and SIGTERM
    run_command(APP, main)
