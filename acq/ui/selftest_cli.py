"""``acq selftest`` on the command line: one line per check as it completes, a summary, or ``--json``."""

from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path

import click
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from acq.commissioning.selftest import SLOW_MOVE, Stopped, run_selftest
from acq.commissioning.selftest_checks import Check
from acq.config import bench_label, load_bench, load_profile, resolve_profile_path
from acq.process_signals import stop_reason
from acqcore.errors import EXIT_INTERRUPTED, ConfigError
from drivers.limits import refuse_beyond_limits

MARK = {"pass": "[green]✓[/]", "warn": "[yellow]⚠[/]", "fail": "[bold red]✗[/]"}
STAGES = ("devices", "streams", "motion", "identification")
#: The identification check's profile on a bench acq moves.
DEFAULT_PROFILE = "triangle_0.2s"


def check_line(check: Check) -> str:
    """``✓ stage · name  figure`` and, unless it passed, ``→ fix`` on the next line (rich markup)."""
    line = f"{MARK[check.status]} [bold]{check.stage} · {escape(check.name)}[/]  {escape(check.figure)}"
    return line + (f"\n    → {escape(check.fix)}" if check.fix else "")


def summary_table(checks: list[Check]) -> Table:
    """Per stage: checks passed / warned / failed, or not run (what to do next: :func:`next_step`)."""
    table = Table(title="selftest")
    for column in ("stage", "✓", "⚠", "✗", "result"):
        table.add_column(column, justify="left" if column in ("stage", "result") else "right")
    for stage in STAGES:
        mine = [c for c in checks if c.stage == stage]
        n = {s: sum(c.status == s for c in mine) for s in MARK}
        result = ("not run" if not mine else "✗ " + ", ".join(c.name for c in mine if c.status == "fail")
                  if n["fail"] else "⚠ " + ", ".join(c.name for c in mine if c.status == "warn") if n["warn"] else "✓")
        table.add_row(stage, str(n["pass"]), str(n["warn"]), str(n["fail"]), escape(result))
    return table


def next_step(checks: list[Check], bench_path: Path | None, profile_name: str | None) -> str:
    """What to do next, plain text: the first failed check's fix, or the command that records on this bench, with the
    warnings named and what each leaves in doubt (:attr:`Check.affects`: a ⚠ does not stop the bench, and "ready"
    alone under a ⚠ read as a contradiction). Printed under the summary at the terminal's width (as the table's
    caption it wrapped to the table's); ``profile_name`` None: a bench that listens, recorded passively."""
    failed = next((c for c in checks if c.status == "fail"), None)
    if failed is not None:
        return f"stopped at {failed.stage} · {failed.name}: {failed.fix}"
    warned = [c for c in checks if c.status == "warn"]
    ready = "the bench is ready" if not warned else (
        f"the bench is ready, with {len(warned)} warning{'s' * (len(warned) > 1)} ("
        + "; ".join(f"{c.name}: {c.affects}" if c.affects else c.name for c in warned) + ")")
    bench = "" if bench_path is None else f" --bench {bench_path}"
    if profile_name is None:
        return f"{ready}: acq monitor{bench}, or acq record{bench} --duration 10"
    return f"{ready}: acq record --profile {profile_name}{bench}"


def stopped_line(where: str, reason: str) -> str:
    """The one line of a selftest Ctrl-C or SIGTERM stopped (exit 130): no verdict on the bench, not a failed check;
    ``where``: "during identification" (a recording it stopped), "after motion · direction" (elsewhere)."""
    return f"acq: selftest interrupted {where} ({reason}): no verdict on the bench — run acq selftest again to check it"


def selftest_json(checks: list[Check], bench_path: str) -> dict[str, object]:
    """``{"bench", "passed", "stopped_at", "checks": [...]}``."""
    failed = next((c for c in checks if c.status == "fail"), None)
    return {"bench": bench_path, "passed": failed is None,
            "stopped_at": None if failed is None else f"{failed.stage} · {failed.name}",
            "checks": [c.to_json_dict() for c in checks]}


@click.command("selftest")
@click.option("--bench", "bench_path", type=click.Path(path_type=Path), default=None,
              help="Bench TOML (default: the simulated bench configs/benches/sim.toml).")
@click.option("--profile", "profile_name", default=None,
              help="Profile of the identification check (name in configs/profiles/ or a TOML path; default "
                   f"{DEFAULT_PROFILE}); none on a bench with [drive] motion = \"external\", which is checked on the "
                   "machine's own motion.")
@click.option("--fast", is_flag=True, help="Simulated parts run as fast as possible instead of in real time.")
@click.option("--keep", "keep_dir", type=click.Path(path_type=Path), default=None,
              help="Keep the selftest's sessions in this folder (default: a temporary folder, removed).")
@click.option("--json", "as_json", is_flag=True, help="Print the checks as JSON.")
def selftest_command(bench_path: Path | None, profile_name: str | None, fast: bool, keep_dir: Path | None,
                     as_json: bool) -> int:
    """Check the bench and its config against the data: devices, streams, a slow move, an identification.

    Each check prints ✓ / ⚠ / ✗ with its figure; a ✗ says what to change in which config key and stops the
    run. Exit code 0 when nothing failed, 2 when the devices refused the config at opening, 130 when Ctrl-C or
    SIGTERM stopped it (one line: no verdict on the bench), 1 otherwise. A bench with
    [drive] motion = "external" is checked on the machine's own motion: acq commands none there.
    """
    bench = load_bench(bench_path)
    if bench.listens() and profile_name is not None:
        raise ConfigError(f"--profile {profile_name}: {bench_path} has [drive] motion = \"external\": acq commands no "
                          "motion there and checks the bench on the machine's own motion — leave out --profile")
    if not bench.listens():
        profile_name = profile_name or DEFAULT_PROFILE
    profile = None if profile_name is None else load_profile(profile_name)
    if profile is not None:  # acq moves the joint: its slow move and the profile within [limits], before any device
        for motion, name in ((SLOW_MOVE, "acq selftest's slow move (acq/commissioning/selftest.py SLOW_MOVE)"),
                             (profile, str(resolve_profile_path(profile_name)))):
            refuse_beyond_limits(motion, bench, name, bench_label(bench_path))
    work_dir = keep_dir if keep_dir is not None else Path(tempfile.mkdtemp(prefix="acq-selftest-"))
    out = Console()
    checks: list[Check] = []
    try:
        for check in run_selftest(bench, profile, work_dir, fast=fast):
            checks.append(check)
            if not as_json:
                out.print(check_line(check))
    except (Stopped, KeyboardInterrupt) as e:  # the person stopped it: not a fault of the bench
        where = (f"during {e.stage}" if isinstance(e, Stopped) else
                 f"after {checks[-1].stage} · {checks[-1].name}" if checks else "before its first check")
        click.echo(stopped_line(where, e.reason if isinstance(e, Stopped) else stop_reason(e)),
                   err=True)  # one plain line (rich would wrap it)
        return EXIT_INTERRUPTED
    finally:
        if keep_dir is None:
            shutil.rmtree(work_dir, ignore_errors=True)
    if as_json:
        click.echo(json.dumps(selftest_json(checks, str(bench_path or "configs/benches/sim.toml")), indent=2))
    else:
        out.print(summary_table(checks))
        out.print(escape(next_step(checks, bench_path, profile_name)), soft_wrap=True)  # "[motor]" is not markup
    failed = next((c for c in checks if c.status == "fail"), None)
    return 0 if failed is None else int(failed.values.get("exit_code", 1))  # 2: a config the devices refused
