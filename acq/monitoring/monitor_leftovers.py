"""What a restarted monitor finds in its folder: the window files an earlier run left, each with what to do with it.

A window of this monitor (session tag ``monitor_window``; its ``monitor_id`` this monitor's) that the catalogue has is
only counted again (its raw files kept or deleted by retention as before). One the catalogue has not is filed by the
restart: a capture the stop cut (status ``recording``: repaired in place unless damaged — repair would copy a damaged
file beside it, ``acq check`` does that) or that did not complete otherwise is filed ``interrupted`` with its reason, a
complete one is analysed. Another monitor's window copied here is never filed: retention may delete it for the disk
budget only when that monitor would (:func:`~acq.monitoring.monitor_windows.copies_deletable`). A file that is not a
readable session, or not a window, is not the monitor's to file or delete.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

from acq.monitoring.catalogue import Catalogue, Entry
from acq.monitoring.monitor_scope import MONITOR_TAG, WINDOW_TAG
from acq.monitoring.monitor_windows import copies_deletable
from acq.monitoring.retention import WindowFiles
from acq.recording.reader import load
from acq.recording.repair import repair

#: Why a window found with status ``recording`` on restart is filed ``interrupted`` (and its repair's note).
CUT = "the monitor stopped during this window's capture (found on restart)"


@dataclass(frozen=True)
class Leftover:
    """One window file found in the monitor's folder on a restart.

    Attributes
    ----------
    files : retention's record of it (``copied``: another monitor's window).
    unfiled : this monitor's window without a row in the catalogue: the restart files it.
    interrupted : of an unfiled window whose capture did not complete, the reason it is filed ``interrupted``; None:
        complete, to analyse.
    """

    files: WindowFiles
    unfiled: bool = False
    interrupted: str | None = None


def leftovers(out_dir: Path, monitor_id: str, known: Mapping[str, Entry], catalogue: Catalogue) -> Iterator[Leftover]:
    """The windows among ``out_dir``'s session files, in name order (``known``: this monitor's windows of its joint in
    ``catalogue``, by session id); a cut capture is repaired before it is yielded. Lazily: the caller files each before
    the next is read, as the monitor did when this loop was its own."""
    copies: dict[str, set[str]] = {}  # another monitor's windows copied here that it would delete, by monitor
    for path in sorted(out_dir.glob("*.h5")):
        try:
            session = load(path)
        except Exception:  # noqa: BLE001 - not a readable session: not ours to judge
            continue
        if WINDOW_TAG not in session.tags:
            continue  # not a window: not ours to file or delete
        n, key = int(session.tags[WINDOW_TAG]), str(session.meta.session_id)
        if session.tags.get(MONITOR_TAG, monitor_id) != monitor_id:  # another monitor's, copied here: not ours to file
            owner = str(session.tags[MONITOR_TAG])
            if owner not in copies:
                copies[owner] = copies_deletable(catalogue, owner)
            yield Leftover(WindowFiles(n, path, True, key not in copies[owner], key, copied=True))  # (retention's)
            continue
        if key in known:
            refused = bool(session.damage) and (known[key].error is not None or known[key].verdict == "interrupted")
            yield Leftover(WindowFiles(n, path, True, False, key, refused=refused))
            continue
        files = WindowFiles(n, path, False, False, key)
        if session.status == "recording":
            if not session.damage:  # a damaged one stays as it is (repair would copy it beside: acq check does)
                repair(path, CUT)
            yield Leftover(files, True, CUT)
        elif session.status != "complete":
            yield Leftover(files, True, f"window capture {session.status}: {session.meta.stop_reason}")
        else:
            yield Leftover(files, True)
