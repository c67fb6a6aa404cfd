"""Which windows of a catalogue are one monitor's: its identity, filed with every window, and the scoping by it.

Several monitors may file into one catalogue (``acq monitor --catalogue``: one SQLite file, or a PostgreSQL database
for a plant), and the shipped robot benches all name their joint ``joint1``: the joint's name alone mixed the robots'
windows (a baseline from one robot, the latest K from another). A monitor's identity is made once, when it first
starts in its ``--out`` folder, and kept there (:data:`IDENTITY_FILE`); every window carries it as the session tag
:data:`MONITOR_TAG` (a column of the catalogue too, so a monitor reads back its own windows by an index). Everything
the monitor reads back (its numbering on a restart, the rules its windows were judged by, its trend, its retention) is
its own windows only; and ``acq trend`` / ``acq fleet`` keep the windows of different monitors apart
(:func:`monitors_of`).

The identity is bound to the host and folder it was made for (written beside it in :data:`IDENTITY_FILE`): a copied
folder carried the identity along, and two monitors then filed their windows as one (the review). At a start
elsewhere (:func:`bound_identity`):

* same host, the folder it was made for no longer holds it: the folder was moved (``mv``) — it is the same monitor,
  bound anew, without a word;
* same host, that folder is this one by another path (a bind mount): the same monitor;
* same host, that folder still holds it: a copy — refused, naming the folder it was copied from;
* another host: acq cannot look at the other host's folder — refused, naming host and folder (a folder carried to a
  replacement PC and a disk image cloned for the next station look alike here).

The way on is a flag, not a file to delete: ``--new-identity`` (this folder is another monitor; the windows copied
here stay the monitor's that captured them) or ``--moved`` (it is the same monitor, the one at the old place no
longer runs). Both act only on a folder whose identity is bound elsewhere, so either is harmless left on a service's
command line; asking an engineer to delete a state file invites deleting it in the wrong folder — the original's,
whose history would then be split. A file of an earlier acq holds the identity alone (one line,
``host:folder:suffix``): its binding is read from the identity itself, so a copy made before the upgrade is found too.
"""

from __future__ import annotations

import json
import socket
import uuid
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from acq.monitoring.catalogue import MONITOR_TAG, Entry
from acq.recording.storage import storage_error, write_text_atomically
from acqcore.errors import ConfigError

__all__ = ["IDENTITY_FILE", "MONITOR_TAG", "WINDOW_TAG", "Identity", "bound_identity", "check_user_tags",
           "monitors_of", "read_identity", "split_by_monitor", "window_number", "write_identity"]

#: Session tag of a monitor's window: its number in the monitor from 0 (every window has it, from before identities
#: too). Shown from 1 (:func:`window_number`).
WINDOW_TAG = "monitor_window"


def window_number(tags: Mapping[str, Any]) -> int | None:
    """The window's number as acq shows it everywhere (status lines, alarm text and ``ACQ_WINDOW``, acq trend's rows):
    from 1, the stored :data:`WINDOW_TAG` (from 0) + 1; None for a session that is no monitor window.

    The tag stays as filed (old catalogues keep working); only what a person reads counts from 1, so "window 10" of
    an alarm is row 10 of acq trend (the monitor said "window 9" where the trend said "#10": the new-user trial)."""
    value = tags.get(WINDOW_TAG)
    try:
        return int(value) + 1  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return None
#: The file in a monitor's ``--out`` folder holding its identity and what it is bound to (JSON; one line before).
IDENTITY_FILE = "monitor.id"


@dataclass(frozen=True)
class Identity:
    """A monitor's identity and what it is bound to.

    Attributes
    ----------
    monitor_id : str
        ``<host>:<folder>:<8 hex digits>`` as made (filed with every window as :data:`MONITOR_TAG`).
    host, folder : str or None
        The host name and absolute folder it is bound to (None: unknown).
    catalogue : str or None
        Where its windows are filed: a SQLite file's absolute path or a URL without its password (None: unknown, a
        file of an earlier acq).
    """

    monitor_id: str
    host: str | None
    folder: str | None
    catalogue: str | None = None


def _from_text(text: str) -> Identity:
    """An identity file's content: JSON, or the one line of an earlier acq (its binding read from the identity)."""
    if not text:  # a file there that says nothing: made anew, the folder's windows would be another monitor's
        raise ValueError("the file is empty")
    if text.startswith("{"):
        doc = json.loads(text)
        return Identity(str(doc["monitor_id"]), doc.get("host"), doc.get("folder"), doc.get("catalogue"))
    host, _, rest = text.partition(":")
    folder, _, suffix = rest.rpartition(":")
    if host and folder and len(suffix) == 8 and all(c in "0123456789abcdef" for c in suffix):
        return Identity(text, host, folder)
    return Identity(text, None, None)  # not made by acq: bound where it is next started


def read_identity(out_dir: Path) -> Identity | None:
    """The identity in ``out_dir``'s :data:`IDENTITY_FILE`; None when there is none."""
    path = out_dir / IDENTITY_FILE
    try:
        text = path.read_text(encoding="utf-8").strip()
    except FileNotFoundError:
        return None
    except OSError as e:
        raise storage_error(e, path) from None
    try:
        return _from_text(text)
    except (ValueError, KeyError, TypeError) as e:
        raise ConfigError(f"{path}: not a monitor identity ({e}) — restore it from a backup, or move it away to "
                          "start a new monitor in this folder") from None


def write_identity(out_dir: Path, identity: Identity) -> None:
    """Write ``identity`` to ``out_dir``'s :data:`IDENTITY_FILE` (atomically)."""
    doc = {"monitor_id": identity.monitor_id, "host": identity.host, "folder": identity.folder,
           "catalogue": identity.catalogue}
    write_text_atomically(out_dir / IDENTITY_FILE, json.dumps(doc, indent=1) + "\n")


def _still_there(folder: str, monitor_id: str) -> bool:
    """Whether ``folder`` (on this host) still holds the identity ``monitor_id``."""
    try:
        found = read_identity(Path(folder))
    except (ConfigError, OSError):
        return False
    return found is not None and found.monitor_id == monitor_id


def _same_folder(folder: str, out_dir: Path) -> bool:
    """Whether ``folder`` (on this host) is ``out_dir`` itself, reached by another path (same device and inode)."""
    try:
        return Path(folder).samefile(out_dir)
    except OSError:
        return False


def bound_identity(out_dir: Path, *, new_identity: bool = False, moved: bool = False) -> Identity:
    """The identity of the monitor of ``out_dir``, bound to this host and folder: read and checked, or made (not
    written: :func:`write_identity`).

    ``new_identity`` / ``moved``: the way on for a folder whose identity is bound to another host or folder — a new
    identity, or the same bound here; ignored for a folder whose identity is its own.

    Raises
    ------
    ConfigError
        The folder's identity is bound to another folder that still holds it (a copy), or to another host.
    """
    host, folder = socket.gethostname(), str(out_dir.resolve())
    found = read_identity(out_dir)
    fresh = Identity(f"{host}:{folder}:{uuid.uuid4().hex[:8]}", host, folder)
    if found is None:
        return fresh
    here = replace(found, host=host, folder=folder)
    if found.host is None or (found.host, found.folder) == (host, folder):
        return here
    if found.host == host and _same_folder(str(found.folder), out_dir):
        return here  # the same folder by another path (a bind mount, a network mount's two names): not a copy
    if new_identity:
        return fresh
    if moved or (found.host == host and not _still_there(str(found.folder), found.monitor_id)):
        return here  # the folder moved (nothing left where it was), or the engineer says so
    way = "--new-identity if this is another monitor (the windows copied here stay that one's)"
    if found.host == host:
        raise ConfigError(f"{out_dir}: this folder looks copied from {found.folder} (its {IDENTITY_FILE} is that "
                          f"monitor's, {found.monitor_id}): two monitors would file their windows as one — start it "
                          f"with {way}, or in a new --out")
    raise ConfigError(f"{out_dir}: its {IDENTITY_FILE} was made on host {found.host} for {found.folder} "
                      f"({found.monitor_id}) — a copy would file its windows as that monitor's: start it with {way}, "
                      f"or with --moved if the monitor on {found.host} no longer runs (the folder moved here)")


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
