"""Session paths as given on the command line: one session file, or a batch (a folder or a glob).

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
    """Raise :class:`ConfigError` naming ``path`` when it is missing or a folder (what it holds is not looked at)."""
    if not path.exists():
        raise ConfigError(f"{path}: no such session file")
    if path.is_dir():
        raise ConfigError(f"{path}: is a folder, not a session file")
