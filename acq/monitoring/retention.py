"""Retention of a monitor's raw window files, and its disk budget.

Catalogue rows are always kept; a window's raw files (``<stem>.h5``, ``.result.json``, ``.report.png``,
a transport's raw log) are deleted once the window is done (analysed or marked), except the baseline
windows, the window that raised each alarm, the windows refused as damaged (filed without a K — the analysis
failed, or the capture was cut by a kill — and their file damaged) and the last ``keep`` windows. A refused window's
catalogue row holds no K, only why: its raw file is the only copy of what it recorded (``acq check --repair`` and
``acq analyze --partial`` recover the intact part), and ``--keep`` counts the windows that have a K in the catalogue,
not it. A disk budget is never exceeded: before a window is captured the folder's
size plus the window's expected size must fit, else the oldest unprotected raw files go first, then the oldest of
the last ``keep``, then the oldest refused ones (a disk that damages every window must not stop the capture); when
even that is not enough the window is not captured (and the monitor says so). Without a budget the file system is one
(the monitor makes room for each window the same way), so refused windows are bounded by the disk, and counted in the
monitor's status (``damaged kept``).

Windows of another monitor in the folder (a folder copied, then started with ``--new-identity``: the copied windows
stay the monitor's that captured them) are no window of this one: no baseline or alarm of its history depends on
them, their K is in the catalogue of the monitor that captured them and that monitor's folder keeps their raw files
by its own rules. ``--keep`` does not count them and without a budget they are left alone (another monitor's files
are not ours to delete without need). Under a budget those that monitor does not keep go first, before any of this
monitor's windows: kept, they counted against ``--max-disk`` for ever, so the monitor's own latest windows went
instead, and once they with the baseline filled the budget no window was captured again. Its baseline and alarm windows
(``protected``, as that monitor's catalogue rows say) are never deleted: the folder copied from may be gone, and these
the only raw files of that monitor's history; when they leave no room the window is not captured.
"""

from __future__ import annotations

import math

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class WindowFiles:
    """One window's raw files as retention sees them.

    Attributes
    ----------
    index : the window's number in the monitor (time order).
    path : its session file.
    done : analysed or marked (its catalogue row is written).
    protected : a baseline window or the window that raised an alarm (never deleted).
    key : what the caller knows the window by (e.g. its session id).
    copied : another monitor's window, copied into this folder (unless protected by that monitor, deleted first for
        the budget; never for ``keep``).
    refused : done, its analysis refused it as damaged (never deleted for ``keep``; last for the budget).
    """

    index: int
    path: Path
    done: bool
    protected: bool
    key: str = ""
    copied: bool = False
    refused: bool = False


def raw_files(session_path: Path) -> list[Path]:
    """The files that belong to a session: the ``.h5`` and its siblings named ``<stem>.*``."""
    return sorted(p for p in session_path.parent.glob(f"{session_path.stem}.*") if p.is_file())


def size_bytes(paths: Iterable[Path]) -> int:
    """Total size of the files that exist, bytes."""
    total = 0
    for p in paths:
        try:
            total += p.stat().st_size
        except FileNotFoundError:
            pass
    return total


def folder_bytes(folder: Path) -> int:
    """Size of every file in ``folder`` (not recursive), bytes."""
    return size_bytes(p for p in folder.iterdir() if p.is_file()) if folder.is_dir() else 0


def to_delete(windows: Iterable[WindowFiles], keep: int) -> list[WindowFiles]:
    """This monitor's windows whose raw files go now: done, not protected, not among its last ``keep`` (oldest first);
    never another monitor's copied here, nor one refused as damaged (nor does one count among the last ``keep``)."""
    ordered = sorted((w for w in windows if not w.copied and not w.refused), key=lambda w: w.index)
    last = {w.index for w in ordered[-keep:]} if keep > 0 else set()
    return [w for w in ordered if w.done and not w.protected and w.index not in last]


def make_room(windows: Iterable[WindowFiles], folder: Path, need_bytes: int, budget_bytes: int) -> tuple[
        list[WindowFiles], bool]:
    """Windows to delete so that ``need_bytes`` more fit in ``budget_bytes``, and whether they then fit.

    Other monitors' unprotected windows copied here go first, then unprotected done windows oldest first, the last
    ``keep`` included (the budget outranks ``keep``), then those refused as damaged oldest first; baseline and
    alarming windows (of this monitor or of the one a copy is of) and windows not yet done are never chosen.
    """
    used = folder_bytes(folder)
    chosen: list[WindowFiles] = []
    for w in sorted(windows, key=lambda w: (not w.copied, w.refused, w.index)):
        if used + need_bytes <= budget_bytes:
            break
        if w.done and not w.protected:
            chosen.append(w)
            used -= size_bytes(raw_files(w.path))
    return chosen, used + need_bytes <= budget_bytes


def delete(window: WindowFiles) -> int:
    """Delete a window's raw files; return the bytes freed (a file already gone counts 0)."""
    freed = 0
    for p in raw_files(window.path):
        try:
            size = p.stat().st_size
            p.unlink()
            freed += size
        except FileNotFoundError:
            pass
    return freed


def parse_size(text: str) -> int:
    """``2GB``, ``500MB``, ``1.5GiB``, ``123B`` → bytes; ValueError naming the text otherwise.

    The unit is required: ``--max-disk 2`` was taken as 2 bytes (the new-user trial), where 2 GB was meant."""
    units = {"B": 1, "KB": 10**3, "MB": 10**6, "GB": 10**9, "TB": 10**12,
             "KIB": 2**10, "MIB": 2**20, "GIB": 2**30, "TIB": 2**40}
    s = text.strip().upper().replace(" ", "")
    number = s.rstrip("KMGTIB")
    unit = s[len(number):]
    try:
        value = float(number)
    except ValueError:
        raise ValueError(f"{text!r} is not a size (e.g. 2GB, 500MB)") from None
    if not unit:
        raise ValueError(f"{text!r} has no unit — give one of B, kB, MB, GB, TB, KiB, MiB, GiB, TiB (e.g. {text}GB)")
    if unit not in units or not 0 < value < math.inf:  # nan and inf too (int() of them raised: the trial)
        raise ValueError(f"{text!r} is not a size (e.g. 2GB, 500MB)")
    return int(value * units[unit])
