"""What a monitor's restart in its folder must agree with, and where its machine time goes on.

A restart resumes the folder's windows: its numbering, its baseline, its alarm. It is refused in one line naming what
differs where the new windows would not be comparable with the old ones or would not join them:

* another bench or ``--window`` (:mod:`acq.monitoring.window_bench`), or other alarm rules;
* another ``--catalogue`` than the one its windows are filed in, when that holds none of them: the monitor started
  over in an empty catalogue — numbering from the raw windows left, a new baseline, the alarm forgotten — and the old
  history stayed behind, unseen. The same database under another spelling (another host alias, user or password in the
  URL; a SQLite file moved with its folder) holds the windows and is no refusal. Moving a monitor from SQLite to a
  plant's PostgreSQL is the legitimate case: ``--move-catalogue`` copies its windows there first, then files there.

Not refused: another ``--every``. It spaces the windows and changes neither a window's K nor its interval; watching a
joint more closely after a warning is what an engineer does. Machine time (``monitor_elapsed_s``, the trend's time
axis and a simulated machine's wear) then goes on from the last window at the new spacing (:class:`MachineClock`)
instead of being the window's number × ``--every``, which jumped when ``--every`` changed.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, replace
from pathlib import Path

from acq.monitoring.alarm_rules import AlarmRules, filed_rules
from acq.monitoring.catalogue import Catalogue, Entry
from acq.monitoring.catalogue_backends import is_url, redacted, without_masked_password
from acq.monitoring.monitor_scope import IDENTITY_FILE, WINDOW_TAG, Identity, own_windows, write_identity
from acq.monitoring.trend import ELAPSED_TAG
from acq.monitoring.window_bench import differences
from acqcore.errors import ConfigError
from drivers.config import Bench

#: Session tag of a monitor's window: the --every it was captured with, s (where machine time goes on after a restart).
EVERY_TAG = "monitor_every_s"


def catalogue_text(location: Path | str) -> str:
    """A catalogue as a monitor records it: a SQLite file's absolute path, a URL without its password."""
    return redacted(location) if is_url(location) else str(Path(location).resolve())  # type: ignore[arg-type]


def check_comparable(out_dir: Path, windows: Sequence[Entry], bench: Bench, window_s: float,
                     rules: AlarmRules) -> None:
    """Refuse a restart whose windows would not be comparable with the folder's ``windows`` (oldest first; rules
    compared with those of this joint's)."""
    changed = differences(windows, bench, window_s)
    if changed:
        # K of another measurement chain, scale or window length would join the trend as if the joint had changed
        raise ConfigError(f"{out_dir}: its windows were captured with another bench or window "
                          f"({'; '.join(changed)}): their K is not comparable — start a new --out (or resume "
                          "with the same bench and --window)")
    filed = filed_rules([e for e in windows if e.joint == bench.joint])
    if filed is not None and filed.as_tags() != rules.as_tags():
        # other rules midway re-baselined on windows judged before, the alarm cleared silently (the second trial)
        raise ConfigError(f"{out_dir}: its windows were judged with --baseline-windows "
                          f"{filed.baseline_sessions} --threshold-pct {filed.threshold_pct:g} --ewma-lambda "
                          f"{filed.ewma_lambda:g}: resume with the same, or start a new --out")


def open_bound(out_dir: Path, identity: Identity, location: Path | str, *, move: bool, own_catalogue: Path,
               legacy: bool, check: Callable[[list[Entry]], None]) -> tuple[Catalogue, list[Entry]]:
    """The catalogue at ``location`` opened, ``identity`` bound to it and written, and the monitor's windows there
    (oldest first; with ``legacy`` its windows from before monitors had an identity too) — or a refusal: its windows
    filed in another catalogue (:func:`catalogue_source`), that catalogue out of reach, ``check`` of the windows.

    ``move`` (``--move-catalogue``): the windows are copied from the catalogue they are filed in first. Every refusal
    comes before anything is made or written: a SQLite file that does not exist yet is made only once the start is
    accepted (a refused ``--catalogue new.sqlite`` left an empty file and its folder behind — the last closing note),
    and ``check`` judges the windows where they are filed, before they are copied. The caller closes the catalogue.
    """
    catalogue = Catalogue(location) if is_url(location) or Path(location).is_file() else None
    try:
        windows: list[Entry] = []
        if catalogue is not None:
            catalogue.fill_monitor_ids()  # its windows an earlier acq filed after another one migrated the catalogue
            windows = own_windows(catalogue, identity.monitor_id, unowned=legacy)
        source = catalogue_source(out_dir, identity, location, bool(windows), move=move, own_catalogue=own_catalogue)
        unowned = source == catalogue_text(own_catalogue)
        with _open_source(out_dir, source) if source is not None else nullcontext() as old:
            if old is not None:
                windows = own_windows(old, identity.monitor_id, unowned=unowned)
            check(sorted(windows, key=lambda e: int(e.tags[WINDOW_TAG])))
            catalogue = catalogue or Catalogue(location)
            if old is not None:
                catalogue.copy_windows(old, identity.monitor_id, unowned=unowned)
                windows = own_windows(catalogue, identity.monitor_id, unowned=legacy)
        write_identity(out_dir, replace(identity, catalogue=catalogue_text(location)))
    except BaseException:
        if catalogue is not None:
            catalogue.close()
        raise
    return catalogue, windows


def catalogue_source(out_dir: Path, identity: Identity, location: Path | str, holds_own: bool, *, move: bool,
                     own_catalogue: Path) -> str | None:
    """The catalogue to copy the monitor's windows from before it files into the one at ``location`` (None: none,
    they are there or there are none), or a refusal when its windows are filed elsewhere and ``move`` is not given.

    ``holds_own``: the catalogue at ``location`` already holds windows of this monitor (the same database, or its
    windows moved there). ``own_catalogue``: the folder's own catalogue file; a recorded SQLite catalogue that no
    longer exists was the folder's own when the folder was moved (``mv``) with it: the windows are copied from the one
    it carried, with its windows from before monitors had an identity (a folder's own catalogue holds no other
    monitor's).
    """
    here = catalogue_text(location)
    if identity.catalogue is None or identity.catalogue == here or holds_own:
        return None
    source = identity.catalogue
    if not is_url(source) and not Path(source).is_file():
        carried = Path(source).name == own_catalogue.name  # the folder moved with its own catalogue
        if carried and here == catalogue_text(own_catalogue):
            return None  # which it files into and holds none of its windows (emptied, deleted): as in place, start over
        if not carried or not own_catalogue.is_file():
            # opening it would make an empty catalogue (and its folder) where it was, and copy nothing from it
            raise ConfigError(f"{out_dir}: its windows are filed in {source}, which no longer exists: resume once "
                              "with --catalogue set to where that file is now, then move them with --move-catalogue")
        source = catalogue_text(own_catalogue)
    if not move:
        raise ConfigError(f"{out_dir}: its windows are filed in {source}, not in {here} (--catalogue): "
                          f"resume with --catalogue {source}, or add --move-catalogue to copy them into "
                          f"{here} and file there from now on")
    return source


def _open_source(out_dir: Path, source: str) -> Catalogue:
    """The catalogue ``source`` a monitor's windows are filed in, as its identity records it. A URL's password is
    recorded masked (never stored): it is opened without one, so libpq reads it from ~/.pgpass or PGPASSWORD — the
    mask sent as the password failed with libpq's authentication error. When that fails: one line naming
    ``source`` and the way on, before anything is copied or the identity rewritten."""
    url = without_masked_password(source) if is_url(source) else source
    try:
        return Catalogue(url)
    except ConfigError as e:
        if url == source:
            raise
        reason = str(e).removeprefix(f"{url}: ")
        raise ConfigError(f"{out_dir}: its windows are filed in {source}: {reason} — {IDENTITY_FILE} keeps no "
                          "password: put it in ~/.pgpass or PGPASSWORD (libpq reads them), then restart with "
                          "--move-catalogue") from None


@dataclass(frozen=True)
class MachineClock:
    """Machine time of a monitor's windows, s: from the last window filed (``last_n`` at ``last_s``, captured every
    ``then_s``) on at ``every_s``; a first run starts at window 0, time 0."""

    every_s: float
    last_n: int = -1
    last_s: float = 0.0
    then_s: float | None = None

    @classmethod
    def resumed(cls, windows: Sequence[Entry], every_s: float) -> MachineClock:
        """The clock going on from the newest of ``windows``. A window of an earlier acq has no :data:`EVERY_TAG`: its
        machine time was its number × the --every it was captured with, which gives that --every back (window 0:
        this ``every_s``)."""
        timed = [e for e in windows if WINDOW_TAG in e.tags and ELAPSED_TAG in e.tags]
        if not timed:
            return cls(every_s)
        last = max(timed, key=lambda e: int(e.tags[WINDOW_TAG]))
        n, elapsed_s = int(last.tags[WINDOW_TAG]), float(last.tags[ELAPSED_TAG])
        then_s = float(last.tags[EVERY_TAG]) if EVERY_TAG in last.tags else elapsed_s / n if n > 0 else every_s
        return cls(every_s, n, elapsed_s, then_s)

    def at(self, n: int) -> float:
        """The start of window ``n`` in machine time, s."""
        if self.then_s is None:
            return n * self.every_s
        if n <= self.last_n:
            return self.last_s + (n - self.last_n) * self.then_s
        return self.last_s + self.then_s + (n - self.last_n - 1) * self.every_s
