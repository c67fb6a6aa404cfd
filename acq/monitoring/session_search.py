"""The session files that command-line arguments name: session files, folders and globs (``acq analyze``, the
batch), and the folder each was sought in, where the catalogue goes by default."""

from __future__ import annotations

import glob
from collections.abc import Iterator, Sequence
from pathlib import Path

from acq.recording.paths import GLOB_CHARS, is_batch, require_session_file
from acqcore.errors import ConfigError


def find_sessions(spec: Path | str) -> tuple[list[Path], Path]:
    """The session files (``*.h5``) of a folder or glob, sorted, and the folder they were sought in.

    The folder is where the catalogue goes by default: the folder itself, or a glob's deepest
    folder without wildcards.
    """
    spec = Path(spec)
    if spec.is_dir():
        paths, base = spec.glob("*.h5"), spec
    else:
        paths = (Path(p) for p in glob.glob(str(spec), recursive=True))
        base = Path(*_prefix(spec.parts))
    sessions = sorted(p for p in paths if p.suffix == ".h5" and p.is_file())
    if not sessions:
        raise ConfigError(f"{spec}: no session files (*.h5) found")
    return sessions, base


def find_all_sessions(specs: Sequence[Path | str]) -> tuple[list[Path], Path | None]:
    """The session files of several command-line arguments — session files, folders, globs (also as the shell
    expanded ``par/*.h5``) — each once, sorted; and the folder the catalogue goes in by default: the one all were
    sought in (as a glob's deepest folder without wildcards), None when they lie in different folders (their common
    folder could be /: the review)."""
    found: dict[Path, Path] = {}
    bases: list[Path] = []
    for spec in map(Path, specs):
        if is_batch(spec):
            paths, base = find_sessions(spec)
        else:
            require_session_file(spec)
            paths, base = [spec], spec.parent
        bases.append(base)
        for p in paths:
            found.setdefault(p.resolve(), p)
    if any(b.resolve() != bases[0].resolve() for b in bases):
        return sorted(found.values()), None
    return sorted(found.values()), bases[0]


def _prefix(parts: Sequence[str]) -> Iterator[str]:
    """The path parts before the first one with a wildcard ('.' when the first has one)."""
    if not parts or GLOB_CHARS & set(parts[0]):
        yield "."
        return
    for part in parts:
        if GLOB_CHARS & set(part):
            return
        yield part
