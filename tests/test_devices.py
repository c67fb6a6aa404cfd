"""`acq devices`: every section lists what it finds or says why it is empty; the simulated bench is always there."""

from __future__ import annotations

import json
from types import SimpleNamespace
from typing import Any

import can
import pytest
from serial.tools import list_ports

pytest.importorskip("nidaqmx")  # the stand-in borrows nidaqmx.constants and nidaqmx.errors

import acq.commissioning.devices
from acq.config import DEFAULT_BENCH
from drivers.nidaq import DRIVER_MISSING
from tests.helpers import run_cli
from tests.nidaqmx_standin import StandinDevice, StandinHardware, real_driver_installed, synthetic_currents

NO_CAN = "python-can detects no CAN interface (no adapter plugged in, or its driver is missing)"


@pytest.fixture
def machine(monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    """What the probes see; tests edit it. Starts with no CAN adapter and no serial port."""
    seen: dict[str, Any] = {"can": [{"interface": "virtual", "channel": "channel-0"}], "serial": []}
    monkeypatch.setattr(can, "detect_available_configs", lambda *a, **k: seen["can"])
    monkeypatch.setattr(list_ports, "comports", lambda *a, **k: seen["serial"])
    monkeypatch.setenv("COLUMNS", "250")
    return seen


def devices_json(capsys: pytest.CaptureFixture[str]) -> dict[str, dict[str, Any]]:
    run = run_cli(capsys, "devices", "--json")
    assert run.code == 0, run.err
    return {s["title"]: s for s in json.loads(run.out)}


def use_standin(monkeypatch: pytest.MonkeyPatch, hw: StandinHardware) -> None:
    monkeypatch.setattr(acq.commissioning.devices, "import_nidaqmx", hw.module)


def test_lists_ni_channels_can_and_serial_and_the_sim(monkeypatch: pytest.MonkeyPatch, machine: dict[str, Any],
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    use_standin(monkeypatch, StandinHardware(currents=synthetic_currents(25600.0, 1),
                                             devices=[StandinDevice(), StandinDevice("Dev2", "USB-6211", 2)]))
    machine["can"] = [{"interface": "socketcan", "channel": "can0"}, {"interface": "virtual", "channel": "v"}]
    machine["serial"] = [SimpleNamespace(device="/dev/ttyUSB0", description="FT232R USB UART",
                                         hwid="USB VID:PID=0403:6001")]
    sections = devices_json(capsys)
    assert sections["NI-DAQmx devices"] == {"title": "NI-DAQmx devices", "empty_because": "", "devices": [
        {"device": "cDAQ1Mod1", "kind": "NI 9234",
         "detail": "cDAQ1Mod1/ai0, cDAQ1Mod1/ai1, cDAQ1Mod1/ai2, cDAQ1Mod1/ai3"},
        {"device": "Dev2", "kind": "USB-6211", "detail": "Dev2/ai0, Dev2/ai1"}]}
    assert sections["CAN interfaces (python-can)"]["devices"] == [
        {"device": "can0", "kind": "socketcan", "detail": ""}]
    assert sections["Serial ports (pyserial)"]["devices"] == [
        {"device": "/dev/ttyUSB0", "kind": "FT232R USB UART", "detail": "USB VID:PID=0403:6001"}]
    assert sections["Simulated bench"]["devices"] == [
        {"device": "sim", "kind": "simulated DAQ + drive", "detail": str(DEFAULT_BENCH)}]
    table = run_cli(capsys, "devices").out
    for text in ("NI-DAQmx devices", "USB-6211", "Dev2/ai0, Dev2/ai1", "can0", "/dev/ttyUSB0", "Simulated bench"):
        assert text in table


def test_every_empty_section_says_why(monkeypatch: pytest.MonkeyPatch, machine: dict[str, Any],
                                      capsys: pytest.CaptureFixture[str]) -> None:
    use_standin(monkeypatch, StandinHardware(currents=synthetic_currents(25600.0, 1), devices=[]))
    sections = devices_json(capsys)
    reasons = {title: (s["devices"], s["empty_because"]) for title, s in sections.items()}
    assert reasons == {
        "NI-DAQmx devices": ([], "NI-DAQmx 2025.3.0 is installed but sees no device (check the cable, power, "
                                 "or NI MAX)"),
        "CAN interfaces (python-can)": ([], f"{NO_CAN}; only software buses: virtual"),
        "Serial ports (pyserial)": ([], "pyserial sees no serial port"),
        "Simulated bench": (sections["Simulated bench"]["devices"], ""),
    }
    table = run_cli(capsys, "devices").out
    assert "pyserial sees no serial port" in table and f"{NO_CAN}; only software buses: virtual" in table


def test_driver_missing_in_the_stand_in_empties_the_ni_section(monkeypatch: pytest.MonkeyPatch,
                                                               machine: dict[str, Any],
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    use_standin(monkeypatch, StandinHardware(currents=synthetic_currents(25600.0, 1), driver_installed=False))
    assert devices_json(capsys)["NI-DAQmx devices"]["empty_because"] == DRIVER_MISSING


@pytest.mark.skipif(real_driver_installed(), reason="the NI-DAQmx driver is installed here")
def test_real_nidaqmx_without_driver_says_so(machine: dict[str, Any], capsys: pytest.CaptureFixture[str]) -> None:
    sections = devices_json(capsys)
    assert (sections["NI-DAQmx devices"]["devices"], sections["NI-DAQmx devices"]["empty_because"]) == (
        [], DRIVER_MISSING)
    assert sections["Simulated bench"]["devices"][0]["device"] == "sim"


def test_a_serial_port_is_a_serial_port_and_no_probe_waits_for_a_network_beacon(
        monkeypatch: pytest.MonkeyPatch, machine: dict[str, Any], capsys: pytest.CaptureFixture[str]) -> None:
    """`acq devices` took 4.5 s and listed /dev/ttyS0 as a CAN interface of kind serial: python-can's ``serial``
    detection names every serial port, and its ``socketcand`` detection listens 3.1 s for a server's beacon."""
    use_standin(monkeypatch, StandinHardware(currents=synthetic_currents(25600.0, 1), devices=[]))
    by_interface = {"serial": [{"interface": "serial", "channel": "/dev/ttyS0"}],
                    "socketcand": [{"interface": "socketcand", "host": "10.0.0.9", "port": 29536, "channel": "can0"}],
                    "virtual": [{"interface": "virtual", "channel": "v"}]}
    asked: list[str] = []

    def detect(interfaces: list[str] | None = None) -> list[dict[str, Any]]:
        asked.extend(interfaces if interfaces is not None else sorted(can.interfaces.VALID_INTERFACES))
        return [c for name in asked for c in by_interface.get(name, [])]

    monkeypatch.setattr(can, "detect_available_configs", detect)
    machine["serial"] = [SimpleNamespace(device="/dev/ttyS0", description="n/a", hwid="n/a")]
    sections = devices_json(capsys)
    assert "serial" not in asked and "socketcand" not in asked and "socketcan" in asked
    assert sections["CAN interfaces (python-can)"] == {
        "title": "CAN interfaces (python-can)", "devices": [], "empty_because": f"{NO_CAN}; only software buses: virtual",
        "note": "not looked for: socketcand servers on the network (finding one waits 3 s for its beacon) and "
                "serial-line CAN adapters (their ports are under Serial ports)"}
    assert sections["Serial ports (pyserial)"]["devices"] == [
        {"device": "/dev/ttyS0", "kind": "serial port", "detail": ""}]
