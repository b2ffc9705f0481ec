"""What the apps share on the command line: one-line errors and warnings, and reading an override early.

Every app reports a user error as one line ``<app>: error: <message>`` with exit status 2 (argparse's
own errors included: ``ArgumentParser``), and a warning as one line ``warning: <message>``
(``one_line_warnings``). The Hydra apps (``vical-train``, ``vical-evaluate``, ``vical-record``) check
the command line before Hydra starts: ``check_composes`` turns Hydra's own override errors into one
line, and each app checks what it can (a ``resume=`` directory must exist before Hydra creates it; an
unknown ``policy=`` is one line, not Hydra's traceback).
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import importlib.util
import logging
import os
import sys
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

from vical.apps import entry
from vical.apps.entry import interrupts_as_raised, is_write_fault
from vical.config_checks import ConfigError, SettingError
from vical.signals import interrupts_held

if TYPE_CHECKING:
    from omegaconf import DictConfig

EXIT_USER_ERROR = 2


def report_error(app: str, message: object) -> int:
    """Print ``<app>: error: <message>`` on one line to stderr (a multi-line message joined); return status 2."""
    print(f"{app}: error: {' '.join(str(message).split())}", file=sys.stderr)
    return EXIT_USER_ERROR


def os_error_reason(err: OSError) -> str:
    """An ``OSError`` as a user reads it: the path and the system's reason without Python's ``[Errno N]``, or, for
    one vical raised with its own message, that message."""
    if err.filename is None or err.strerror is None:
        return str(err)
    return f"{err.filename}: {err.strerror.lower()}"


def fail(app: str, err: BaseException) -> NoReturn:
    """Print ``<app>: error: <message>`` on one line to stderr and exit with status 2."""
    raise SystemExit(report_error(app, err))


class ArgumentParser(argparse.ArgumentParser):
    """argparse with vical's one-line errors: ``<prog>: error: <message>`` and exit status 2, no usage block."""

    def error(self, message: str) -> NoReturn:
        raise SystemExit(report_error(self.prog, f"{message} (see {self.prog} --help)"))


class OutputError(Exception):
    """An output path that cannot be used or written; the message names the flag or key and the reason."""


def as_given(flag: str, out: str | os.PathLike) -> str:
    """An output as the command line gives it: ``--out X`` (argparse) or ``out=X`` (a Hydra override)."""
    return f"{flag}{out}" if flag.endswith("=") else f"{flag} {out}"


def _written_as(err: OSError, out: str | os.PathLike) -> str:
    """The file a writer could not write, or ``it`` (the output itself, or one of the temporary siblings the
    atomic writers build it in: a name the user never gave)."""
    if err.filename is None or Path(err.filename) == Path(out) or ".tmp-" in str(err.filename):
        return "it"
    return str(err.filename)


def cannot_write(flag: str, out: str | os.PathLike, err: OSError, kept: str = "") -> str:
    """``--out X: cannot write it (no space left on device); <kept>; free space there or choose another directory``:
    an ``OSError`` without Python's ``[Errno N]``; ``kept`` says what the command kept (nothing half-written)."""
    reason = (err.strerror or os.strerror(err.errno or 0)).lower()
    full = err.errno in (errno.ENOSPC, errno.EDQUOT)
    remedy = "free space there or choose another directory" if full else "choose another directory"
    what = f"{as_given(flag, out)}: cannot write {_written_as(err, out)} ({reason})"
    return "; ".join(part for part in (what, kept, remedy) if part)


# What a command that met a full disk kept: the line that an interrupted one ends with (vical.apps.entry).
AS_IT_WAS = entry.AS_IT_WAS.format(where="it")


@contextlib.contextmanager
def write_faults_in_one_line(app: str, flag: str, out: str | os.PathLike,
                             kept: str | Callable[[], str] = AS_IT_WAS) -> Iterator[None]:  # fmt: skip
    """A full disk or a read-only folder met inside the block ends ``app`` with one line (what it could not write,
    what it kept, what to do) and status 2; raised as ``SystemExit``, which Hydra's job runner lets through. An error
    that an interrupt caused is raised as the interrupt (``interrupts_as_raised``), which it lets through too."""
    try:
        with interrupts_as_raised():
            yield
    except OSError as err:
        if not is_write_fault(err):
            raise
        line = cannot_write(flag, out, err, kept() if callable(kept) else kept)
        raise SystemExit(report_error(app, line)) from None


class RunLogFile(logging.FileHandler):
    """``vical-train``'s ``train.log``: a record that a full disk or a read-only folder refuses is dropped without
    logging's ``--- Logging error ---`` traceback; the run's own writers (checkpoints, TensorBoard) meet the same
    fault and end the command in one line (``write_faults_in_one_line``)."""

    def handleError(self, record: logging.LogRecord) -> None:
        if not is_write_fault(sys.exc_info()[1]):
            super().handleError(record)


def check_creatable(flag: str, out: str | os.PathLike) -> Path:
    """``out`` as a Path; ``OutputError`` when it cannot be made or written: below a file, or where this process
    cannot write (a read-only file system, another user's folder): the folder it is made in and, when it exists,
    itself. Checked before any work, so that none is lost to it."""
    path = Path(out)
    existing = next(d for d in path.absolute().parents if d.exists())
    if not existing.is_dir():
        raise OutputError(f"{as_given(flag, out)} cannot be created: {existing} is a file; choose another directory")
    for folder in (existing, path) if path.is_dir() else (existing,):
        if not os.access(folder, os.W_OK | os.X_OK):
            raise OutputError(f"{as_given(flag, out)}: {folder} is not writable; choose another directory")
    return path


def argparse_main(
    app: str,
    parser: argparse.ArgumentParser,
    run: Callable[[argparse.Namespace], Any],
    errors: tuple[type[Exception], ...],
    flags: dict[str, str],
    argv: list[str] | None,
) -> int:
    """The console entry point of an argparse command: exit status 0, or 2 with one line on stderr.

    ``errors`` are the refusals whose message is the user's to read, settings they name spelled as the
    command's ``flags`` (``vical.config_checks.SettingError``); a file the readers could not open gives its path
    and the reason, without Python's ``[Errno N]``.
    """
    one_line_warnings()
    try:
        args = parser.parse_args(argv)
    except SystemExit as done:  # --help (0), or a bad argument whose line argparse printed (2)
        return int(done.code or 0)
    try:
        run(args)
    except errors as exc:
        return report_error(app, exc.with_flags(flags) if isinstance(exc, SettingError) else str(exc))
    except OSError as exc:
        if is_write_fault(exc) and getattr(args, "out", None):
            return report_error(app, cannot_write("--out", args.out, exc, AS_IT_WAS))
        return report_error(app, os_error_reason(exc))
    return 0


def plain(node: Any) -> Any:
    """A config node as plain dicts and lists, interpolations resolved (anything else as it is)."""
    from omegaconf import OmegaConf  # here: the entry point imports this module before the heavy imports

    return OmegaConf.to_container(node, resolve=True) if OmegaConf.is_config(node) else node


def _one_line(message, category, filename, lineno, line=None) -> str:
    return f"warning: {' '.join(str(message).split())}\n"


def one_line_warnings() -> None:
    """Print each warning as ``warning: <message>``: users need what happened, not the Python source line."""
    warnings.formatwarning = _one_line


def quiet_library_logs() -> None:
    """Keep libraries' INFO records out of the Hydra apps' console log (PyOpenGL announces an optional module)."""
    logging.getLogger("OpenGL").setLevel(logging.WARNING)


def override_value(argv: list[str], key: str) -> str | None:
    """The string value of a ``key=value`` (or ``+key=value``) override in ``argv``.

    None when absent, null, empty, a sweep, or malformed (Hydra then reports the syntax error itself).
    """
    from hydra.core.override_parser.overrides_parser import OverridesParser  # only the Hydra apps pay its import
    from hydra.errors import HydraException

    for arg in argv:
        if arg.lstrip("+").startswith(f"{key}="):
            try:
                (override,) = OverridesParser.create().parse_overrides([arg])
            except HydraException:
                return None
            value = None if override.is_sweep_override() else override.value()
            return value if isinstance(value, str) and value else None
    return None


def check_composes(conf_dir: str | os.PathLike, config_name: str, argv: list[str]) -> DictConfig | None:
    """Compose ``<conf_dir>/<config_name>.yaml`` with the command line's overrides, as Hydra is about to.

    Hydra reports its own errors (an unknown key without ``+``, an unknown group choice, bad override
    syntax) in several lines and exits with status 1; composing first turns them into one ``ConfigError``
    line. Returns the composed config (without the ``hydra`` node), or None for a command line with Hydra
    flags (``-m``, ``--cfg``, ...): those are left to Hydra.
    """
    from hydra import compose, initialize_config_dir  # only the Hydra apps pay its import
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    if any(arg.startswith("-") for arg in argv):
        return None
    try:
        with initialize_config_dir(config_dir=str(conf_dir), version_base="1.3"):
            return compose(config_name=config_name, overrides=argv)
    except (HydraException, OmegaConfBaseException) as err:
        raise ConfigError(_hydra_message(err)) from None


def _hydra_message(err: Exception) -> str:
    """Hydra's message without its search path and links; a list of available options on the same line."""
    from hydra.errors import OverrideParseException

    text = str(err).split("\nConfig search path")[0].split("\nSee https")[0]
    if isinstance(err, OverrideParseException):
        return f"cannot parse the override {err.override!r}: {text}"
    head, _, options = text.partition("\n\nAvailable options in ")
    if not options:
        return head
    group, _, names = options.partition(":")
    return f"{head.rstrip('.')}; the available options in {group} are: {', '.join(names.split())}"


# Hydra launcher choices -> (module of the plugin, what to install).
LAUNCHER_PLUGINS = {
    "joblib": ("hydra_plugins.hydra_joblib_launcher", "pip install hydra-joblib-launcher"),
    "submitit_slurm": ("hydra_plugins.hydra_submitit_launcher", "pip install 'vical[slurm]'"),
    "submitit_local": ("hydra_plugins.hydra_submitit_launcher", "pip install 'vical[slurm]'"),
    "vical_slurm": ("hydra_plugins.hydra_submitit_launcher", "pip install 'vical[slurm]'"),
    "ray": ("hydra_plugins.hydra_ray_launcher", "pip install hydra-ray-launcher (in its own environment)"),
    "ray_aws": ("hydra_plugins.hydra_ray_launcher", "pip install hydra-ray-launcher (in its own environment)"),
    "vical_ray": ("hydra_plugins.hydra_ray_launcher", "pip install hydra-ray-launcher (in its own environment)"),
}


def check_launcher(argv: list[str]) -> None:
    """Refuse in one line a ``hydra/launcher=`` whose plugin is not installed, saying what to install."""
    choice = override_value(argv, "hydra/launcher")
    if choice not in LAUNCHER_PLUGINS:
        return  # the basic launcher, or a name Hydra itself will refuse with the list of choices
    module, install = LAUNCHER_PLUGINS[choice]
    if importlib.util.find_spec(module) is None:
        raise ConfigError(f"hydra/launcher={choice} needs a Hydra launcher plugin that is not installed: {install}")


# Ctrl-C and SIGTERM held from a Hydra app's start until its task begins (``hydra_start_up_held``).
_HYDRA_START_UP = contextlib.ExitStack()


@contextlib.contextmanager
def hydra_start_up_held() -> Iterator[None]:
    """Ctrl-C and SIGTERM held while the command line is composed and Hydra starts the job, until the task begins
    (``task_begins``): OmegaConf turns an interrupt that lands inside it into its own error, which Hydra reports in
    several lines with status 1 (``vical.signals``). Held at most for the composition, ~1 s."""
    with _HYDRA_START_UP:
        _HYDRA_START_UP.enter_context(interrupts_held())
        yield


def task_begins() -> None:
    """The Hydra task's first step: an interrupt held through the start-up is raised here, as the task's own."""
    _HYDRA_START_UP.close()


def check_then_run(
    app: str,
    conf_dir: str | os.PathLike,
    config_name: str,
    check_settings: Callable[[DictConfig], Any],
    hydra_main: Callable[[], Any],
    user_errors: tuple[type[BaseException], ...],
) -> None:
    """Console entry point of a Hydra app: the command line composed and the settings checked first (one
    line ``<app>: error: ...`` and status 2 for ``user_errors`` and Hydra's own override errors), then Hydra."""
    one_line_warnings()
    with hydra_start_up_held():
        try:
            cfg = check_composes(conf_dir, config_name, sys.argv[1:])
            if cfg is not None:  # None with Hydra flags (-m, --cfg, ...): the app checks under Hydra
                check_settings(cfg)
        except user_errors as err:
            fail(app, err)
        hydra_main()
