"""``acq devices``: the command line of :mod:`acq.commissioning.devices` (the sections as a table or JSON)."""

from __future__ import annotations

import json

import click
from rich.console import Console

from acq.commissioning.devices import discover
from acq.ui.display import sections_table


@click.command("devices")
@click.option("--json", "as_json", is_flag=True, help="Print the sections as JSON.")
def devices_command(as_json: bool) -> int:
    """List NI devices and AI channels, CAN interfaces, serial ports and the simulated bench."""
    sections = discover()
    if as_json:
        click.echo(json.dumps([s.to_json_dict() for s in sections], indent=2))
    else:
        Console().print(sections_table(sections))
    return 0
