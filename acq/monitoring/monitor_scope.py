"""Which windows of a catalogue are one monitor's: its identity, filed with every window, and the scoping by it.

Several monitors may file into one catalogue (``acq monitor --catalogue``: one SQLite file, or a PostgreSQL database
for a plant), and the shipped robot benches all name their joint ``joint1``: the joint's name alone mixed the robots'
windows (a baseline from one robot, the latest K from another). A monitor's identity is made once, when it first
starts in its ``--out`` folder, and kept there (:data:`IDENTITY_FILE`, so a moved or copied folder is still the same
monitor); every window carries it as the session tag :data:`MONITOR_TAG`. Everything the monitor reads back (its
numbering on a restart, the rules its windows were judged by, its trend, its retention) is its own windows only; and
``acq trend`` / ``acq fleet`` keep the windows of different monitors apart (:func:`monitors_of`).
"""

from __future__ import annotations

import socket
import uuid
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from acq.monitoring.catalogue import Entry
from acq.recording.storage import storage_error, write_text_atomically
from acqcore.errors import ConfigError

#: Session tag of a monitor's window: the identity of the monitor that captured it.
MONITOR_TAG = "monitor_id"
#: Session tag of a monitor's window: its number in the monitor (every window has it, from before identities too).
WINDOW_TAG = "monitor_window"
#: The file in a monitor's ``--out`` folder holding its identity (one line).
IDENTITY_FILE = "monitor.id"


def monitor_identity(out_dir: Path) -> str:
    """The identity of the monitor of ``out_dir``: read from its :data:`IDENTITY_FILE`, or made and written there.

    A new identity is ``<host>:<folder>:<8 hex digits>`` — readable in a shared catalogue (which machine, which
    folder), and unique even when a folder of the same name is made anew on the same host.
    """
    path = out_dir / IDENTITY_FILE
    try:
        text = path.read_text(encoding="utf-8").strip()
    except FileNotFoundError:
        text = ""
    except OSError as e:
        raise storage_error(e, path) from None
    if text:
        return text
    identity = f"{socket.gethostname()}:{out_dir.resolve()}:{uuid.uuid4().hex[:8]}"
    write_text_atomically(path, identity + "\n")
    return identity


def own_windows(entries: Iterable[Entry], identity: str, *, legacy: bool) -> list[Entry]:
    """The entries that the monitor ``identity`` filed.

    ``legacy``: windows filed before monitors had an identity (no :data:`MONITOR_TAG`) are the monitor's too — true
    only for the catalogue of its own folder, which no other monitor wrote to then.
    """
    return [e for e in entries if e.tags.get(MONITOR_TAG) == identity or (legacy and MONITOR_TAG not in e.tags)]


def check_user_tags(tags: Mapping[str, Any], reserved: Sequence[str]) -> None:
    """Refuse a ``--tag`` of ``acq monitor`` that would overwrite a tag the monitor files itself."""
    for key in tags:
        if key in reserved or key == MONITOR_TAG:
            raise ConfigError(f"--tag {key}=…: acq monitor files {key} itself with every window — "
                              "choose another key")


def monitors_of(entries: Iterable[Entry]) -> list[str]:
    """The distinct monitor identities among ``entries``, in the order first seen."""
    return list(dict.fromkeys(str(e.tags[MONITOR_TAG]) for e in entries if MONITOR_TAG in e.tags))


def split_by_monitor(entries: Sequence[Entry]) -> dict[str | None, list[Entry]]:
    """One joint's sessions (oldest first) as the histories to judge apart: each monitor's windows apart, and the
    sessions of no monitor (a bench's recordings, imports) under None; with a single monitor, windows from before
    monitors had an identity are its own. Without any monitor: all together, as before identities. A bench's sessions
    judged with a monitor's windows made the bench's first sessions the monitor's baseline (the second read)."""
    monitors = monitors_of(entries)
    if not monitors:
        return {None: list(entries)}
    groups: dict[str | None, list[Entry]] = {m: [] for m in monitors}
    for e in entries:
        if MONITOR_TAG in e.tags:
            key: str | None = str(e.tags[MONITOR_TAG])
        else:
            key = monitors[0] if len(monitors) == 1 and WINDOW_TAG in e.tags else None
        groups.setdefault(key, []).append(e)
    return groups
