"""An exclusive publish (``acq export`` without ``--force``) on a file system without hard links (FAT, exFAT on a USB
stick: ``link`` fails with EPERM): the name taken by an ``O_EXCL`` placeholder and a rename over it. No FAT mount is
available to the tests, so ``os.link`` stands for that file system (a mock of the hardware's behaviour only); the
rename, the placeholder and the files are real."""

from __future__ import annotations

import errno
import os
import signal
from pathlib import Path

import pytest

from acq.recording.storage import atomic_path
from acqcore.errors import StorageError


@pytest.fixture
def no_hard_links(monkeypatch: pytest.MonkeyPatch) -> None:
    def link(src: object, dst: object, *a: object, **kw: object) -> None:
        raise OSError(errno.EPERM, "Operation not permitted")
    monkeypatch.setattr(os, "link", link)


def _publish(target: Path, text: str) -> None:
    with atomic_path(target, exclusive=True) as tmp:
        tmp.write_text(text)


def test_the_name_is_taken_once_and_no_temp_is_left(tmp_path: Path, no_hard_links: None) -> None:
    target = tmp_path / "x.csv"
    _publish(target, "first")
    with pytest.raises(FileExistsError):
        _publish(target, "second")
    assert target.read_text() == "first" and [p.name for p in tmp_path.iterdir()] == ["x.csv"]


def test_a_failed_rename_leaves_no_placeholder(tmp_path: Path, no_hard_links: None,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """The empty placeholder left behind made every later export say 'exists'."""
    def replace(src: object, dst: object) -> None:
        raise OSError(errno.EIO, "Input/output error")
    monkeypatch.setattr(os, "replace", replace)
    target = tmp_path / "x.csv"
    with pytest.raises(StorageError, match="x.csv"):
        _publish(target, "first")
    assert list(tmp_path.iterdir()) == []


def test_a_ctrl_c_as_the_rename_returns_keeps_the_complete_file(tmp_path: Path, no_hard_links: None,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """The review: a Ctrl-C raised as ``os.replace`` returned was caught by the placeholder's cleanup, which then removed
    the file the rename had just completed — nothing left. Now the signal is held over the placeholder and the rename
    and raised after them: the export is interrupted, its file whole."""
    real_replace = os.replace

    def replace_then_ctrl_c(src: object, dst: object) -> None:
        real_replace(src, dst)  # type: ignore[arg-type]
        signal.raise_signal(signal.SIGINT)
    monkeypatch.setattr(os, "replace", replace_then_ctrl_c)
    target = tmp_path / "x.csv"
    with pytest.raises(KeyboardInterrupt):
        _publish(target, "first")
    assert target.read_text() == "first" and [p.name for p in tmp_path.iterdir()] == ["x.csv"]
