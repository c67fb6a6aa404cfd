"""The install hint of an optional extra works where acq runs from: a source tree (git clone, editable install) is
installed from its path, since PyPI does not know this project."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from acq.install import install_hint
from tests.helpers import run_cli

ROOT = Path(__file__).resolve().parents[1]  # this checkout: pyproject.toml and the acq package


def test_hint_names_the_source_tree_or_the_package(tmp_path: Path) -> None:
    assert install_hint("fleet") == f"pip install -e '{ROOT}[fleet]'"
    spaced = tmp_path / "my clone"
    spaced.mkdir()
    (spaced / "pyproject.toml").write_text("[project]\nname = 'acq'\n")
    assert install_hint("cluster", spaced) == f"pip install -e '{spaced}[cluster]'"
    assert install_hint("fleet", tmp_path) == "pip install 'acq[fleet]'"  # no pyproject.toml: an installed wheel


@pytest.mark.parametrize(("option", "value", "module", "needs"), [
    ("--catalogue", "postgresql://u@localhost/db", "psycopg", "--catalogue postgresql://…: needs psycopg 3 — "),
    ("--scheduler", "tcp://127.0.0.1:9", "distributed", "--scheduler needs Dask distributed: "),
])
def test_missing_extra_is_one_line_with_a_hint_that_works_from_this_checkout(
        option: str, value: str, module: str, needs: str, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, module, None)  # `import psycopg` / `from distributed import …` fail
    (tmp_path / "a.h5").write_bytes(b"")  # the batch stops at the catalogue or the workers, before reading it
    run = run_cli(capsys, "analyze", str(tmp_path), option, value, "--partial", "--no-report")
    assert run.code == 2
    extra = "fleet" if module == "psycopg" else "cluster"
    assert run.err == f"acq: error: {needs}pip install -e '{ROOT}[{extra}]'\n"
