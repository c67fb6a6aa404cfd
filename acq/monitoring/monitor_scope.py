"""Which windows of a catalogue are one monitor's: its identity, filed with every window, and the scoping by it.

Several monitors may file into one catalogue (``acq monitor --catalogue``: one SQLite file, or a PostgreSQL database
for a plant), and the shipped robot benches all name their joint ``joint1``: the joint's name alone mixed the robots'
windows (a baseline from one robot, the latest K from another). A monitor's identity is made once, when it first
starts in its ``--out`` folder, and kept there (:data:`IDENTITY_FILE`); every window carries it as the session tag
:data:`MONITOR_TAG` (a column of the catalogue too, so a monitor reads back its own windows by an index). Everything
the monitor reads back (its numbering on a restart, the rules its windows were judged by, its trend, its retention) is
its own windows only; and ``acq trend`` / ``acq fleet`` keep the windows of different monitors apart
(:func:`monitors_of`).

The identity is bound to the machine and folder it was made for (written beside it in :data:`IDENTITY_FILE`): a
copied folder carried the identity along, and two monitors then filed their windows as one (the review). What tells a
machine and a folder, and what each assumes:

* the machine-id (``/etc/machine-id``, or D-Bus's ``/var/lib/dbus/machine-id``): made once per installation of the
  operating system and kept across reboots. Two different ids are two machines — a folder carried to a replacement
  PC, a disk image cloned for the next station whose id was made anew. An equal id proves less: a container image
  may carry one file for every container made from it on every machine, and a disk cloned block by block keeps it;
  a container without systemd has none (or the host's, mounted in). A container running systemd without a kept id
  gets a new one at every start: its restarts are refused until ``--moved``.
* the folder's filesystem object (its filesystem's id and the folder's inode): the same folder object, whatever
  path reaches it — kept by ``mv`` within a filesystem, a bind mount at another path, a container's volume across
  restarts; never by a copy (``cp``, ``rsync``, ``tar``, a backup restored), which makes a new folder. The filesystem
  is told by ``statvfs``'s ``f_fsid``, which ext4 and btrfs derive from the filesystem's UUID (kept across remounts,
  reboots, a block device numbered anew — a volume attached to another node); where a filesystem gives none (0)
  by ``st_dev``, which assumes the device keeps its number: true of a disk's partition (its major:minor), not always
  of network filesystems, whose numbers are handed out at mount — there a restart after a remount falls back to the
  host name and path. A block-level clone of the disk keeps both (see the machine-id).
* the host name (``socket.gethostname()``): set once per machine outside containers; a container's is new at every
  container start (Docker's container id, Kubernetes' pod name), so it tells nothing there about the machine.

"Another host" is then: another machine-id (both known), or — the folder not being the same folder object — another
host name. At a start (:func:`bound_identity`):

* the same folder object, on a machine whose id is not another: the same monitor, bound anew, without a word (a
  container restarted with a new host name, a bind mount, ``mv``);
* same host, the folder it was made for no longer holds it: the folder was moved (``mv`` across filesystems) — it
  is the same monitor;
* same host, that folder is this one by another path (an identity of an earlier acq, which kept no folder object):
  the same monitor;
* same host, that folder still holds it: a copy — refused, naming the folder it was copied from;
* another host: acq cannot look at the other host's folder — refused, naming host and folder (a folder carried to a
  replacement PC and a copy for the next station look alike here). A copy on a machine of the same machine-id (or
  none), host name and path — a cloned disk whose host name was kept — is not told from the original.

The way on is a flag, not a file to delete: ``--new-identity`` (this folder is another monitor; the windows copied
here stay the monitor's that captured them) or ``--moved`` (it is the same monitor, the one at the old place no
longer runs). Both act only on a folder whose identity is bound elsewhere, so either is harmless left on a service's
command line; asking an engineer to delete a state file invites deleting it in the wrong folder — the original's,
whose history would then be split. A file of an earlier acq holds the identity alone (one line,
``host:folder:suffix``): its binding is read from the identity itself, so a copy made before the upgrade is found too.
"""

from __future__ import annotations

import json
import os
import re
import socket
import uuid
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from acq.monitoring.catalogue import MONITOR_TAG, Catalogue, Entry
from acq.recording.storage import storage_error, write_text_atomically
from acq.recording.tags import parse_tags
from acqcore.errors import ConfigError

__all__ = ["IDENTITY_FILE", "MONITOR_TAG", "WINDOW_TAG", "Identity", "bound_identity", "check_user_tags",
           "folder_object", "machine_id", "monitor_and_tags", "monitors_of", "own_windows", "read_identity",
           "split_by_monitor", "window_number", "write_identity"]

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
#: Where the machine's id is read, first found first (systemd's, then D-Bus's; a Debian without systemd has the latter).
MACHINE_ID_FILES = ("/etc/machine-id", "/var/lib/dbus/machine-id")


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
    machine_id : str or None
        The machine's id (:data:`MACHINE_ID_FILES`; None: it has none, or a file of an earlier acq).
    folder_object : tuple of int or None
        The folder's filesystem object, ``(filesystem id, inode)`` (:func:`folder_object`; None: a file of an earlier
        acq).
    """

    monitor_id: str
    host: str | None
    folder: str | None
    catalogue: str | None = None
    machine_id: str | None = None
    folder_object: tuple[int, int] | None = None


def _from_text(text: str) -> Identity:
    """An identity file's content: JSON, or the one line of an earlier acq (its binding read from the identity)."""
    if not text:  # a file there that says nothing: made anew, the folder's windows would be another monitor's
        raise ValueError("the file is empty")
    if text.startswith("{"):
        doc = json.loads(text)
        inode = doc.get("folder_object")
        return Identity(str(doc["monitor_id"]), doc.get("host"), doc.get("folder"), doc.get("catalogue"),
                        doc.get("machine_id"), None if inode is None else (int(inode[0]), int(inode[1])))
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
    except (ValueError, KeyError, TypeError, IndexError) as e:
        raise ConfigError(f"{path}: not a monitor identity ({e}) — restore it from a backup, or move it away to "
                          "start a new monitor in this folder") from None


def write_identity(out_dir: Path, identity: Identity) -> None:
    """Write ``identity`` to ``out_dir``'s :data:`IDENTITY_FILE` (atomically)."""
    doc = {"monitor_id": identity.monitor_id, "host": identity.host, "folder": identity.folder,
           "catalogue": identity.catalogue, "machine_id": identity.machine_id,
           "folder_object": None if identity.folder_object is None else list(identity.folder_object)}
    write_text_atomically(out_dir / IDENTITY_FILE, json.dumps(doc, indent=1) + "\n")


def _still_there(folder: str, monitor_id: str) -> bool:
    """Whether ``folder`` (on this host) still holds the identity ``monitor_id``."""
    try:
        found = read_identity(Path(folder))
    except (ConfigError, OSError):
        return False
    return found is not None and found.monitor_id == monitor_id


def machine_id() -> str | None:
    """This machine's id (:data:`MACHINE_ID_FILES`: 32 hex digits); None when it has none (a container without
    systemd) or it is not set yet (systemd's ``uninitialized`` of a first boot)."""
    for path in MACHINE_ID_FILES:
        try:
            text = Path(path).read_text(encoding="ascii").strip()
        except (OSError, UnicodeDecodeError):
            continue
        if re.fullmatch(r"[0-9a-f]{32}", text):
            return text
    return None


def folder_object(folder: Path) -> tuple[int, int]:
    """``(filesystem id, inode)`` of ``folder``: the filesystem by ``statvfs``'s ``f_fsid`` (ext4, btrfs: from its
    UUID), by ``st_dev`` where that is 0 (the module's docstring says what each assumes)."""
    try:
        stat, fsid = folder.stat(), os.statvfs(folder).f_fsid
    except OSError as e:
        raise storage_error(e, folder) from None
    return (fsid or stat.st_dev, stat.st_ino)


def _same_folder(folder: str, out_dir: Path) -> bool:
    """Whether ``folder`` (on this host) is ``out_dir`` itself, reached by another path (same device and inode)."""
    try:
        return Path(folder).samefile(out_dir)
    except OSError:
        return False


def bound_identity(out_dir: Path, *, new_identity: bool = False, moved: bool = False) -> Identity:
    """The identity of the monitor of ``out_dir`` (an existing folder), bound to this machine and folder: read and
    checked, or made (not written: :func:`write_identity`). See the module's docstring for what is taken for the same
    machine and folder.

    ``new_identity`` / ``moved``: the way on for a folder whose identity is bound to another host or folder — a new
    identity, or the same bound here; ignored for a folder whose identity is its own.

    Raises
    ------
    ConfigError
        The folder's identity is bound to another folder that still holds it (a copy), or to another host.
    """
    host, folder, machine = socket.gethostname(), str(out_dir.resolve()), machine_id()
    found = read_identity(out_dir)
    fresh = Identity(f"{host}:{folder}:{uuid.uuid4().hex[:8]}", host, folder, None, machine, folder_object(out_dir))
    if found is None:
        return fresh
    here = replace(found, host=host, folder=folder, machine_id=machine, folder_object=fresh.folder_object)
    other_machine = None not in (found.machine_id, machine) and found.machine_id != machine
    if found.host is None or (not other_machine and found.folder_object == fresh.folder_object):
        return here  # not made by acq; or this very folder (a container restarted with another host name, a bind mount)
    same_host = not other_machine and found.host == host
    if same_host and (found.folder == folder or _same_folder(str(found.folder), out_dir)):
        return here  # the same folder by another path (of an identity that kept no folder object), or restored there
    if new_identity:
        return fresh
    if moved or (same_host and not _still_there(str(found.folder), found.monitor_id)):
        return here  # the folder moved (nothing left where it was), or the engineer says so
    way = "--new-identity if this is another monitor (the windows copied here stay that one's)"
    if same_host:
        raise ConfigError(f"{out_dir}: this folder looks copied from {found.folder} (its {IDENTITY_FILE} is that "
                          f"monitor's, {found.monitor_id}): two monitors would file their windows as one — start it "
                          f"with {way}, or in a new --out")
    machine_text = f" (machine-id {found.machine_id}, this one's {machine})" if other_machine else ""
    raise ConfigError(f"{out_dir}: its {IDENTITY_FILE} was made on host {found.host}{machine_text} for {found.folder} "
                      f"({found.monitor_id}) — a copy would file its windows as that monitor's: start it with {way}, "
                      f"or with --moved if the monitor on {found.host} no longer runs (the folder moved here)")


def check_user_tags(tags: Mapping[str, Any], reserved: Sequence[str]) -> None:
    """Refuse a ``--tag`` of ``acq monitor`` that would overwrite a tag the monitor files itself."""
    for key in tags:
        if key in reserved or key == MONITOR_TAG:
            raise ConfigError(f"--tag {key}=…: acq monitor files {key} itself with every window — "
                              "choose another key")


def own_windows(catalogue: Catalogue, monitor: str, joint: str | None = None, *, unowned: bool) -> list[Entry]:
    """The windows of ``monitor`` in ``catalogue`` (of ``joint``; None: any), oldest first — never another monitor's of
    a joint of the same name in a shared catalogue; with ``unowned`` its windows without an identity too (only in the
    catalogue of its own folder): a query on the catalogue's monitor_id column."""
    return [e for e in catalogue.entries(joint, monitor=monitor, unowned=unowned) if WINDOW_TAG in e.tags]


def monitor_and_tags(texts: Sequence[str]) -> tuple[str | None, dict[str, str | float]]:
    """``acq trend`` / ``acq fleet``'s ``--tag KEY=VALUE`` texts as the monitor they name (``monitor_id=ID``, given at
    most once: :func:`parse_tags` refuses a key given twice; None: none) — read by the catalogue's monitor_id column
    and its index — and the other tags (matched in Python). The identity is its text as given: parsed as a number, an
    identity of digits (a monitor.id not made by acq) matched none of its windows."""
    tags = parse_tags(texts)  # first: a malformed or repeated tag is refused before anything is read
    monitor = None
    for text in texts:
        key, sep, value = text.partition("=")
        if sep and key.strip() == MONITOR_TAG:
            monitor = value.strip()
    return monitor, {key: value for key, value in tags.items() if key != MONITOR_TAG}


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
