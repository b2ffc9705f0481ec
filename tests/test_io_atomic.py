"""Atomic writes: outputs get the permissions an ordinary open/mkdir would give them; a killed writer's
temporary siblings are removed by the next write to the same place, nobody else's."""

import os
import socket
import stat
import subprocess
import sys

import pytest

from vical.io.atomic import atomic_directory, remove_stale_temporaries, write_text_atomic


@pytest.fixture
def umask_022():
    old = os.umask(0o022)
    yield
    os.umask(old)


def test_atomic_file_respects_the_umask(tmp_path, umask_022):
    path = tmp_path / "sub" / "camchain.yaml"
    write_text_atomic(path, "cam0: {}\n")
    assert path.read_text() == "cam0: {}\n"
    assert stat.S_IMODE(path.stat().st_mode) == 0o644


def test_atomic_directory_respects_the_umask(tmp_path, umask_022):
    with atomic_directory(tmp_path / "rec") as tmp:
        (tmp / "a.txt").write_text("x")
    assert stat.S_IMODE((tmp_path / "rec").stat().st_mode) == 0o755
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".rec.tmp-")]


def test_failed_swap_puts_the_old_directory_back(tmp_path, monkeypatch):
    final = tmp_path / "rec"
    final.mkdir()
    (final / "old.txt").write_text("old")
    real_rename = os.rename

    def rename_failing_into_place(src, dst):
        if str(src).startswith(str(tmp_path / ".rec.tmp-")):
            raise OSError("disk gone")
        real_rename(src, dst)

    monkeypatch.setattr(os, "rename", rename_failing_into_place)
    with pytest.raises(OSError, match="disk gone"), atomic_directory(final, overwrite=True) as tmp:
        (tmp / "new.txt").write_text("new")
    assert (final / "old.txt").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec"]


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_a_killed_writers_temporary_siblings_are_removed_by_the_next_write(tmp_path):
    host = socket.gethostname()
    dead = tmp_path / f".rec.tmp-{_dead_pid()}@{host}.k1ll3d"
    dead.mkdir()
    (dead / "images.npz").write_bytes(b"")  # what a recording killed mid-write leaves
    stale_file = tmp_path / f".camchain.yaml.tmp-{_dead_pid()}@{host}.x7"
    stale_file.write_text("half")
    alive = tmp_path / f".rec.tmp-{os.getpid()}@{host}.busy"  # a writer that still runs
    elsewhere = tmp_path / f".rec.tmp-{_dead_pid()}@another-host.nfs"  # this host cannot tell
    legacy = tmp_path / ".rec.tmp-abc123"  # no writer recorded in the name
    for path in (alive, elsewhere, legacy):
        path.mkdir()

    with atomic_directory(tmp_path / "rec") as tmp:
        (tmp / "a.txt").write_text("x")
    assert not dead.exists() and stale_file.exists()  # only the temporaries of the path written
    write_text_atomic(tmp_path / "camchain.yaml", "cam0: {}\n")
    assert not stale_file.exists()
    assert alive.exists() and elsewhere.exists() and legacy.exists()
    assert remove_stale_temporaries(tmp_path) == []
