"""Atomic writes: outputs get the permissions an ordinary open/mkdir would give them."""

import os
import stat

import pytest

from vical.io.atomic import atomic_directory, write_text_atomic


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
