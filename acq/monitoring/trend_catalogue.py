"""The catalogues a trend reads (``acq trend`` / ``acq fleet`` FOLDER… [--catalogue C]…) and a joint's trend loaded
from one (:func:`load_trend`): its sessions filtered on tags, refused when the windows of several monitors share the
joint's name."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from acq.monitoring.catalogue import Catalogue
from acq.monitoring.catalogue_backends import is_url, redacted
from acq.monitoring.monitor_scope import MONITOR_TAG, monitor_and_tags, monitors_of, split_by_monitor
from acq.monitoring.session_outcome import CATALOGUE_NAME
from acq.monitoring.trend import Trend, compute_trend
from acq.recording.storage import refused_write
from acq.recording.tags import tags_match
from acqcore.errors import ConfigError


class NoSessions(ConfigError):
    """The catalogue has no session of the joint asked for, or there is no catalogue file yet. ``location``: the
    catalogue (a URL without its password); ``joints``: the joints it has. ``awaited``: a monitor may still file the
    joint's first window there, so ``acq view --trend`` waits for it — the catalogue is empty, or not made yet in a
    folder that exists, may be written and holds no session file; not for a folder that is not there (a mistyped
    path was waited for for ever), one of sessions never catalogued, or a catalogue of other joints."""

    def __init__(self, message: str, location: Path | str, joints: Sequence[str] = (), *, awaited: bool) -> None:
        super().__init__(message)
        self.location, self.joints, self.awaited = location, list(joints), awaited


def _not_a_folder(folder: Path) -> str | None:
    """Why ``folder`` cannot hold a catalogue (it is not there, or is a file), else None."""
    if folder.is_dir():
        return None
    return f"{folder} is a file, not a folder" if folder.exists() else f"the folder {folder} does not exist"


def catalogue_location(folder: Path | None, catalogue: Path | str | None) -> Path | str:
    """The catalogue to read: ``catalogue`` (a file or URL) or FOLDER/catalogue.sqlite; an error when no file."""
    path = catalogue or (folder or Path("sessions")) / CATALOGUE_NAME
    if not is_url(path) and not Path(path).is_file():
        sessions = folder or Path("sessions")
        refused = None if catalogue else refused_write(sessions)  # acq analyze can make no catalogue there
        missing = _not_a_folder(Path(path).parent if catalogue else sessions)
        fill = (missing if missing else
                f"fill it with acq analyze FOLDER/ --catalogue {path}" if catalogue else
                f"{sessions} is not writable ({refused}): fill one with acq analyze {sessions}/ --result-dir DIR, "
                "then acq trend DIR" if refused else f"fill one with acq analyze {sessions}/ first")
        uncatalogued = not catalogue and sessions.is_dir() and any(sessions.glob("*.h5"))
        awaited = Path(path).parent.is_dir() and refused is None and not uncatalogued
        raise NoSessions(f"{path}: no catalogue — {fill}", path, awaited=awaited)
    return path


def catalogue_sources(folders: Sequence[Path], catalogues: Sequence[Path | str]) -> list[tuple[str, Path | str]]:
    """The catalogues of ``acq fleet`` / ``acq trend`` FOLDER… [--catalogue C]…, each with its label (the folder or
    catalogue as given, a URL without its password): FOLDER/catalogue.sqlite of each folder, then each catalogue;
    none given: ``sessions/catalogue.sqlite`` (label ''). A catalogue named twice is refused (it would be read twice).
    """
    sources = [(str(f), catalogue_location(f, None)) for f in folders] + \
        [(redacted(str(c)) if is_url(c) else str(c), catalogue_location(None, c)) for c in catalogues] \
        or [("", catalogue_location(None, None))]
    if len({str(loc) if is_url(loc) else str(Path(loc).resolve()) for _, loc in sources}) < len(sources):
        raise ConfigError(f"{' '.join(label for label, _ in sources)}: a catalogue is given twice")
    return sources


def load_trend(folder: Path | None, catalogue_path: Path | str | None, joint: str, tags: Sequence[str] = (),
               no_monitor: bool = False, **options: Any) -> Trend:
    """The trend of ``joint`` from a catalogue (``folder``/catalogue.sqlite or ``catalogue_path``), sessions
    filtered on ``tags`` (``KEY=VALUE``) — with ``no_monitor`` (``--no-monitor``) only the sessions of no monitor (a
    bench's recordings, imports: :func:`split_by_monitor`'s None); ``options`` go to :func:`compute_trend`."""
    monitor, wanted = monitor_and_tags(tags)
    if no_monitor and monitor is not None:
        raise ConfigError(f"--no-monitor and --tag {MONITOR_TAG}={monitor}: give one of them")
    with Catalogue(catalogue_location(folder, catalogue_path), read_only=True) as catalogue:
        entries = [e for e in catalogue.entries(joint, monitor=monitor) if tags_match(e.tags, wanted)]
        if no_monitor:
            entries = split_by_monitor(entries).get(None, [])
        tagged = f" tagged {' '.join(tags)}" if tags else ""
        tagged += " of no monitor" if no_monitor else ""
        if not entries:
            joints = catalogue.joints()
            raise NoSessions(f"{catalogue.path}: no sessions of joint {joint}{tagged} "
                             f"(joints: {', '.join(joints) or 'none'})", catalogue.path, joints, awaited=not joints)
        histories = split_by_monitor(entries)
        if len(histories) > 1:  # several monitors (or one and a bench's sessions), one joint name: one trend mixes them
            monitors = monitors_of(entries)
            robots = sorted({str(e.tags["robot"]) for e in entries if "robot" in e.tags})
            others = len(histories.get(None, []))
            what = (f"the windows of {len(monitors)} monitor{'s' if len(monitors) > 1 else ''} "
                    f"({', '.join(monitors)})" + (f" and {others} session(s) of no monitor" if others else ""))
            ways = [f"--tag {MONITOR_TAG}=ID", *(["--no-monitor (those of no monitor)"] if others else []),
                    *([f"--tag robot=R ({', '.join(robots)})"] if robots else [])]
            raise ConfigError(f"{catalogue.path}: joint {joint}{tagged} has {what} — trend one: "
                              + (", ".join(ways[:-1]) + " or " + ways[-1] if len(ways) > 1 else ways[0]))
    return compute_trend(joint, entries, **options)
