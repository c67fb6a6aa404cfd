"""How to install one of acq's optional extras (``pyproject.toml``'s ``[project.optional-dependencies]``), in the
words that work where this acq was imported from."""

from __future__ import annotations

import shlex
from pathlib import Path

#: The folder holding the ``acq`` package: a source tree (git clone, editable install) when ``pyproject.toml`` is
#: there too; an installed wheel has none beside it in site-packages.
SOURCE_ROOT = Path(__file__).resolve().parents[1]


def install_hint(extra: str, source_root: Path = SOURCE_ROOT) -> str:
    """The command installing ``extra``: ``pip install -e '<source tree>[extra]'`` (README's form with the tree's path)
    when acq runs from a source tree, whose project PyPI does not know; else ``pip install 'acq[extra]'``."""
    if (source_root / "pyproject.toml").is_file():
        return f"pip install -e {shlex.quote(f'{source_root}[{extra}]')}"
    return f"pip install {shlex.quote(f'acq[{extra}]')}"
