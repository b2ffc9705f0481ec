"""Atomic writes: outputs appear at their final path complete or not at all.

Files are written to a temporary sibling and moved into place with ``os.replace``; directories
are built in a temporary sibling directory and renamed. A crash mid-write leaves at most a
hidden ``.<name>.tmp-<pid>@<host>.*`` sibling, never a partial file or directory at the final
path. The writer's process id and host in that name let a later write recognise a sibling whose
writer is gone (killed, or the machine crashed) and remove it (``remove_stale_temporaries``).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _give_default_permissions(path: Path, base: int) -> None:
    """``mkstemp``/``mkdtemp`` create private entries (0600/0700); outputs get what ``open`` would give."""
    os.chmod(path, base & ~_umask())


def temporary_prefix(final: Path) -> str:
    """``.<name>.tmp-<pid>@<host>.``: the name prefix of this process's temporary siblings of ``final``."""
    return f".{final.name}.tmp-{os.getpid()}@{socket.gethostname()}."


def _writer_is_gone(owner: str) -> bool:
    """Whether the writer ``<pid>@<host>`` of a temporary sibling no longer runs (only this host can tell)."""
    pid, at, host = owner.partition("@")
    if not (pid.isdigit() and at and host == socket.gethostname()):
        return False  # another machine's, or named before writers were recorded: leave it alone
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        pass  # another user's live process
    return False


def remove_stale_temporaries(directory: str | os.PathLike, name: str | None = None) -> list[Path]:
    """Remove the temporary siblings (of the entry ``name``, or of any) in ``directory`` whose writer is gone.

    A writer killed mid-write (``kill -9``, a crash) cannot remove its temporary sibling; the next
    write to the same place does, so that nothing half-written accumulates or blocks it.
    """
    directory = Path(directory)
    if not directory.is_dir():
        return []
    removed = []
    for entry in directory.iterdir():
        head, marker, tail = entry.name.rpartition(".tmp-")
        if not (marker and head.startswith(".")) or (name is not None and head != f".{name}"):
            continue
        if _writer_is_gone(tail.rsplit(".", 1)[0]):
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry, ignore_errors=True)
            else:
                entry.unlink(missing_ok=True)
            removed.append(entry)
    return removed


def _fsync_file(path: Path) -> None:
    with open(path, "rb") as f:
        os.fsync(f.fileno())


@contextlib.contextmanager
def atomic_file(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success it replaces ``path`` atomically.

    The caller writes the whole file to the yielded path. If the body raises, the temporary file
    is removed and ``path`` is left untouched.
    """
    final = Path(path)
    final.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(final.parent, final.name)
    fd, tmp_name = tempfile.mkstemp(prefix=temporary_prefix(final), dir=final.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        _give_default_permissions(tmp, 0o666)
        yield tmp
        _fsync_file(tmp)
        os.replace(tmp, final)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    with atomic_file(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


@contextlib.contextmanager
def files_together(directory: str | os.PathLike) -> Iterator[Callable[[str], Path]]:
    """Write several files (or folders) of ``directory`` as one result: yields ``path_of(name)``, the temporary
    path to write the entry ``name`` to; when the body ends, the entries are moved into place one after another
    (each rename whole, a folder through ``replace_directory``), none of them before all are written; if the body
    raises, none is moved and nothing is left. A ``directory`` that does not exist yet is built aside and renamed
    into place whole (``atomic_directory``): an interrupted run leaves no empty one behind."""
    final = Path(directory)
    if not final.exists():
        with atomic_directory(final) as built:
            yield lambda name: built / name
        return
    staging = Path(tempfile.mkdtemp(prefix=temporary_prefix(final / "files"), dir=final))
    written: list[str] = []

    def path_of(name: str) -> Path:
        written.append(name)
        return staging / name

    try:
        yield path_of
        for name in written:
            if (staging / name).is_dir():
                replace_directory(staging / name, final / name)
            else:
                os.replace(staging / name, final / name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def check_can_write_dir(path: str | os.PathLike, overwrite: bool) -> Path:
    """Raise ``FileExistsError`` when ``path`` exists and ``overwrite`` is false; return it as a Path."""
    final = Path(path)
    if final.exists() and not overwrite:
        raise FileExistsError(f"{final} already exists; pass overwrite=True to replace it")
    if final.exists() and not final.is_dir():
        raise FileExistsError(f"{final} exists and is not a directory; remove it or choose another path")
    return final


@contextlib.contextmanager
def atomic_directory(path: str | os.PathLike, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary sibling directory; on success it is renamed to ``path``.

    With ``overwrite`` an existing directory at ``path`` is replaced: it is first renamed aside,
    the new directory renamed into place, then the old one deleted; if the second rename fails the
    old directory is renamed back. ``path`` never holds a partial directory, but between the two
    renames (two system calls) it briefly does not exist. If the body raises, the temporary
    directory is deleted and ``path`` is untouched.
    """
    final = check_can_write_dir(path, overwrite)
    final.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(final.parent, final.name)
    tmp = None
    try:  # from its creation on: an interrupt right after it still removes it (one inside mkdtemp leaves it, named
        # as stale for the next run: remove_stale_temporaries)
        tmp = Path(tempfile.mkdtemp(prefix=temporary_prefix(final), dir=final.parent))
        _give_default_permissions(tmp, 0o777)
        yield tmp
        _replace_directory(tmp, final, overwrite)
    except BaseException:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
        raise


def _replace_directory(tmp: Path, final: Path, overwrite: bool) -> None:
    if final.exists():
        check_can_write_dir(final, overwrite)
    replace_directory(tmp, final)


def unused_sibling(path: str | os.PathLike, label: str) -> Path:
    """A name beside ``path`` that nothing uses (``<name>.<label>-<random>``, reserved and released at once): where
    a replacement is built before ``replace_directory`` puts it in place."""
    path = Path(path)
    sibling = Path(tempfile.mkdtemp(prefix=f"{path.name}.{label}-", dir=path.parent))
    sibling.rmdir()
    return sibling


def replace_directory(new: str | os.PathLike, final: str | os.PathLike) -> None:
    """Put the complete directory ``new`` at ``final`` (a sibling): the old ``final`` is renamed aside, ``new``
    renamed into place, then the old one deleted; if the second rename fails the old one is renamed back."""
    new, final = Path(new), Path(final)
    if not final.exists():
        os.rename(new, final)
        return
    old = unused_sibling(final.with_name(f".{final.name}"), "old")
    os.rename(final, old)
    try:
        os.rename(new, final)
    except BaseException:
        os.rename(old, final)  # put the previous content back
        raise
    shutil.rmtree(old, ignore_errors=True)
