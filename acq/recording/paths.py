"""Session paths: as given on the command line (one session file, or a batch: a folder or a glob), and the name of
a new session file.

Light on purpose (no numpy, h5py or analysis): the command line checks a path here before it loads
the libraries that read or analyse the file, so a mistyped path is one line at once.
"""

from __future__ import annotations

from pathlib import Path

from acqcore.errors import ConfigError

GLOB_CHARS = frozenset("*?[")


def is_batch(spec: Path | str) -> bool:
    """True when ``spec`` names a folder or a glob pattern rather than one session file."""
    return Path(spec).is_dir() or bool(GLOB_CHARS & set(str(spec)))


def require_session_file(path: Path) -> None:
    """Raise :class:`ConfigError` naming ``path`` when it is missing, a folder or no regular file (a device such as
    /dev/zero, a pipe, a socket: it would read as "empty (0 bytes)"); what it holds is not looked at."""
    if not path.exists():
        raise ConfigError(f"{path}: no such session file")
    if path.is_dir():
        raise ConfigError(f"{path}: is a folder, not a session file")
    if not path.is_file():
        raise ConfigError(f"{path}: not a regular file (a device, pipe or socket), not a session file")


def new_session_path(out_dir: Path, joint: str, created_utc: str) -> Path:
    """``<out_dir>/<UTC start>_<joint>.h5`` (file-system safe), ``_2``, ``_3`` … if taken."""
    stamp = created_utc.replace("+00:00", "").replace(":", "-")
    path = Path(out_dir) / f"{stamp}_{joint}.h5"
    if path.resolve().parent != Path(out_dir).resolve() or "/" in joint or "\0" in joint:
        raise ConfigError(f"joint {joint!r}: not usable in a file name (the session must stay in {out_dir})")
    n = 2
    while path.exists():
        path = Path(out_dir) / f"{stamp}_{joint}_{n}.h5"
        n += 1
    return path
