"""The NI DAQ adapter against a stand-in of the nidaqmx API, and against the real nidaqmx without its driver."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

pytest.importorskip("nidaqmx")  # the stand-in borrows nidaqmx.constants and nidaqmx.errors

import acq.commissioning.devices
import drivers.nidaq
from acq.config import DEFAULT_BENCH, load_bench, load_profile
from acq.recording.recorder import Recorder
from acq.recording.reader import load
from drivers.nidaq import DRIVER_MISSING, NidaqCurrentSource
from drivers.sim.bench import SimBench
from drivers.sim.drive import SimDrive
from nidaqmx import constants
from tests.helpers import run_cli
from tests.nidaqmx_standin import StandinDevice, StandinHardware, real_driver_installed, synthetic_currents

RATE_HZ, BLOCK, A_PER_V = 25600, 2560, 10.0
NI_9234_CHANNELS = "cDAQ1Mod1/ai0, cDAQ1Mod1/ai1, cDAQ1Mod1/ai2, cDAQ1Mod1/ai3"


def write_bench(folder: Path, **daq: object) -> Path:
    """The simulated bench with an NI-DAQmx ``[daq]`` section (the drive stays simulated)."""
    settings: dict[str, object] = {"driver": "nidaqmx", "rate_hz": RATE_HZ, "channels": ["i_a"],
                                   "physical_channels": ["cDAQ1Mod1/ai0"], "sensor_A_per_V": A_PER_V} | daq
    head, _, rest = DEFAULT_BENCH.read_text().partition("[daq]")
    _, _, tail = rest.partition("[drive]")
    keys = "\n".join(f"{k} = {json.dumps(v, ensure_ascii=False)}" for k, v in settings.items())
    path = folder / "nidaq.toml"
    path.write_text(f"{head}[daq]\n{keys}\n\n[drive]{tail}")
    return path


@pytest.fixture
def hardware(monkeypatch: pytest.MonkeyPatch) -> StandinHardware:
    """An NI 9234 behind the stand-in, with synthetic currents; `acq` imports it instead of nidaqmx."""
    hw = StandinHardware(currents=synthetic_currents(RATE_HZ, 1), sensor_gain=A_PER_V)
    monkeypatch.setattr(drivers.nidaq, "import_nidaqmx", hw.module)
    monkeypatch.setattr(acq.commissioning.devices, "import_nidaqmx", hw.module)
    return hw


def record(capsys: pytest.CaptureFixture[str], bench: Path, out: Path, duration_s: float = 1.0):  # noqa: ANN201
    return run_cli(capsys, "record", "--profile", "triangle_0.2s", "--bench", str(bench), "--fast",
                   "--duration", str(duration_s), "--out", str(out), "--no-analyze")  # the driver's part only


def last_line(text: str) -> str:
    """The last line of stderr (a failure at device start follows the progress bar's first frame)."""
    return text.strip().splitlines()[-1]


@pytest.mark.parametrize("timeout_every", [0, 7], ids=["whole-reads", "reads-timing-out-partway"])
def test_5s_acquisition_loses_no_sample(tmp_path: Path, timeout_every: int) -> None:
    bench = load_bench(write_bench(tmp_path))
    sim = SimBench(bench, realtime=False, keep_history=True)
    hw = StandinHardware(currents=sim.current_samples, sensor_gain=A_PER_V, timeout_every=timeout_every)
    source = NidaqCurrentSource(bench.daq, lib=hw.module())
    result = Recorder(bench, load_profile("triangle_0.2s"), source, SimDrive(bench, sim), tmp_path / "s", 5.0).run()

    s = load(result.path)
    assert s.status == "complete"
    index = s.current.sample_index()
    assert index.size >= 5 * RATE_HZ
    np.testing.assert_array_equal(index, np.arange(index.size))  # by index: nothing lost, nothing repeated
    np.testing.assert_allclose(s.current.phases_a["i_a"], sim.current_samples(0, index.size)[0], rtol=0, atol=1e-12)
    details = [e.detail for e in s.events]
    assert [e for e in s.events if e.kind in ("gap", "error")] == []
    assert f"card acquired {index.size} samples per channel, {index.size} read, 0 left in the buffer at stop" in details
    task = hw.tasks[0]
    assert task.timing.sample_mode == constants.AcquisitionType.CONTINUOUS
    assert task.in_stream.input_buf_size == 5 * RATE_HZ  # buffer_s = 5 s
    assert len(hw.arrays_read_into) == 1  # every read went into the one preallocated array
    assert task.closed
    if not timeout_every:
        np.testing.assert_array_equal(s.current.block_count, BLOCK)


def test_coerced_rate_is_stored(tmp_path: Path, hardware: StandinHardware,
                                capsys: pytest.CaptureFixture[str]) -> None:
    run = record(capsys, write_bench(tmp_path, rate_hz=25000), tmp_path / "s")
    assert run.code == 0, run.err
    (path,) = (tmp_path / "s").glob("*.h5")
    with h5py.File(path, "r") as f:
        assert f["current"].attrs["rate_hz"] == 25600.0  # NI 9234: 51.2 kS/s / 2, the next rate up
        assert json.loads(f.attrs["bench_json"])["daq"]["rate_hz"] == 25000  # what was asked, kept too
    s = load(path)
    assert s.current.rate_hz == 25600.0
    assert s.current.device == "cDAQ1Mod1 (NI 9234): i_a=cDAQ1Mod1/ai0"
    assert s.current.sample_count == 25600 and set(s.current.block_count) == {BLOCK}


def test_iepe_and_ac_coupling_are_set_where_asked(tmp_path: Path, hardware: StandinHardware) -> None:
    bench = load_bench(write_bench(tmp_path, iepe_excitation_A=0.002, coupling="ac", channels=["i_a", "i_b"],
                                   physical_channels=["cDAQ1Mod1/ai0", "cDAQ1Mod1/ai1"]))
    source = NidaqCurrentSource(bench.daq, lib=hardware.module())
    assert source.start().channels == ("i_a", "i_b")
    source.stop()
    for channel in hardware.tasks[0].ai_channels.channels:
        assert channel.ai_excit_src == constants.ExcitationSource.INTERNAL
        assert channel.ai_excit_val == 0.002 and channel.ai_coupling == constants.Coupling.AC


def test_driver_missing_is_one_line_exit_1_and_no_file(tmp_path: Path, hardware: StandinHardware,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    hardware.driver_installed = False
    run = record(capsys, write_bench(tmp_path), tmp_path / "s")
    assert (run.code, last_line(run.err)) == (1, f"acq: error: {DRIVER_MISSING}")
    assert not (tmp_path / "s").exists()


@pytest.mark.parametrize(("daq", "message"), [
    ({"physical_channels": ["Dev9/ai0"]},
     "NI-DAQmx device 'Dev9' not found (channel 'Dev9/ai0' in [daq] physical_channels; devices present: "
     "cDAQ1Mod1; DAQmx error -200220)"),
    ({"physical_channels": ["cDAQ1Mod1/ai7"]},
     "NI-DAQmx channel 'cDAQ1Mod1/ai7' is invalid on device 'cDAQ1Mod1' (NI 9234): Physical channel specified "
     f"does not exist on this device. (DAQmx error -200170; its AI channels: {NI_9234_CHANNELS})"),
], ids=["device-not-found", "channel-invalid"])
def test_device_and_channel_errors_name_both(tmp_path: Path, hardware: StandinHardware,
                                             capsys: pytest.CaptureFixture[str], daq: dict[str, object],
                                             message: str) -> None:
    run = record(capsys, write_bench(tmp_path, **daq), tmp_path / "s")
    assert (run.code, last_line(run.err)) == (1, f"acq: error: {message}")
    assert "Traceback" not in run.err and not (tmp_path / "s").exists()
    assert all(task.closed for task in hardware.tasks)


def test_iepe_refused_by_the_module_names_channel_and_setting(tmp_path: Path, hardware: StandinHardware,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    hardware.devices = [StandinDevice(name="cDAQ1Mod1", product_type="NI 9215", supports_iepe=False)]
    run = record(capsys, write_bench(tmp_path, iepe_excitation_A=0.002), tmp_path / "s")
    assert run.code == 1
    assert last_line(run.err).startswith("acq: error: NI-DAQmx channel cDAQ1Mod1/ai0 refused [daq] "
                                        "iepe_excitation_A = 0.002, coupling = 'dc': Specified property is not "
                                        "supported by the device or is not applicable to the task. "
                                        "(DAQmx error -200452)")


@pytest.mark.parametrize(("code", "what", "advice"), [
    (-200279, "the host buffer was overwritten before it was read",
     "raise [daq] buffer_s (now 5 s) or block_s (now 0.1 s), or lower rate_hz"),
    (-200361, "the device's onboard memory overflowed (the bus did not keep up)",
     "lower [daq] rate_hz or the channel count, or give the device a bus of its own; raise buffer_s (now 5 s) "
     "and block_s (now 0.1 s) so the host drains it in larger reads"),
    (-200714, "the driver could not move data to the host fast enough",
     "raise [daq] buffer_s (now 5 s) and block_s (now 0.1 s), or lower rate_hz"),
])
def test_overflow_ends_the_recording_cleanly(tmp_path: Path, hardware: StandinHardware,
                                             capsys: pytest.CaptureFixture[str], code: int, what: str,
                                             advice: str) -> None:
    hardware.overflow_code, hardware.overflow_after = code, 2 * RATE_HZ
    run = record(capsys, write_bench(tmp_path), tmp_path / "s", duration_s=5.0)
    message = (f"NI-DAQmx buffer overflow after 51200 samples per channel read (2.000 s), DAQmx error {code}: "
               f"{what} — {advice}")
    assert run.code == 1 and "Traceback" not in run.err
    assert f"failed: {message} — everything recorded up to the stop is kept in " in " ".join(run.err.split())
    (path,) = (tmp_path / "s").glob("*.h5")
    s = load(path)
    assert (s.status, s.attrs["stop_reason"]) == ("failed", message)
    np.testing.assert_array_equal(s.current.sample_index(), np.arange(2 * RATE_HZ))  # the data read is kept
    details = [e.detail for e in s.events if e.stream == "current"]
    assert f"DAQmx error {code}: {what}; 51200 samples per channel read" in details
    assert any(d.startswith("sample count mismatch at stop: card acquired ") for d in details)
    assert hardware.tasks[0].closed


@pytest.mark.parametrize(("miscount", "kind", "detail"), [
    (-1, "error", "sample count mismatch at stop: card acquired 5119 samples per channel, 5120 read"),
    (130000, "gap", "sample count mismatch at stop: card acquired 135120 samples per channel, 5120 read, "
                    "130000 unread exceed the 128000-sample buffer"),
])
def test_card_count_cross_checked_at_stop(tmp_path: Path, hardware: StandinHardware, miscount: int, kind: str,
                                          detail: str) -> None:
    source = NidaqCurrentSource(load_bench(write_bench(tmp_path)).daq, lib=hardware.module())
    source.start()
    blocks = [source.read(0.2), source.read(0.2)]
    assert [(b.first_index, b.count) for b in blocks if b is not None] == [(0, BLOCK), (BLOCK, BLOCK)]
    hardware.miscount = miscount
    source.stop()
    source.stop()  # idempotent
    assert [(e.kind, e.detail) for e in source.events()] == [(kind, detail)]


@pytest.mark.parametrize(("daq", "message"), [
    ({"channels": ["i_a", "i_b"]},
     "[daq] channels ['i_a', 'i_b'] and physical_channels ['cDAQ1Mod1/ai0'] must have the same length"),
    ({"block_s": 3.0}, "[daq] block_s = 3 must be at most half of buffer_s = 5"),
])
def test_inconsistent_daq_settings_are_input_errors(tmp_path: Path, hardware: StandinHardware,
                                                    capsys: pytest.CaptureFixture[str], daq: dict[str, object],
                                                    message: str) -> None:
    bench = write_bench(tmp_path, **daq)
    run = record(capsys, bench, tmp_path / "s")
    assert (run.code, last_line(run.err)) == (2, f"acq: error: {bench}: {message}")


@pytest.mark.skipif(real_driver_installed(), reason="the NI-DAQmx driver is installed here")
def test_real_nidaqmx_without_driver_end_to_end(tmp_path: Path) -> None:
    """The installed nidaqmx package, no driver: `acq record` says so in one line, exit 1, no session."""
    bench = write_bench(tmp_path)
    env = {**os.environ, "COLUMNS": "60"}
    run = subprocess.run([sys.executable, "-m", "acq", "record", "--profile", "triangle_0.2s", "--bench", str(bench),
                          "--out", str(tmp_path / "s")], capture_output=True, text=True, env=env, timeout=120)
    assert (run.returncode, run.stderr, run.stdout) == (1, f"acq: error: {DRIVER_MISSING}\n", "")
    assert not (tmp_path / "s").exists()  # the driver is probed when the adapter opens, before any file


def test_hardware_template_documents_every_daq_drive_and_limits_key() -> None:
    from drivers.config import DaqNidaqmx, DriveCanopen, DriveSerial, Limits

    path = DEFAULT_BENCH.parent / "template_hardware.toml"
    bench = load_bench(path)
    assert (bench.daq.driver, bench.drive.driver) == ("nidaqmx", "canopen")
    text = path.read_text()
    for model in (DaqNidaqmx, DriveCanopen, DriveSerial, Limits):
        for key in model.model_fields:
            assert f"\n{key} = " in text or f"\n# {key} = " in text, key


def test_current_channels_scale_by_the_sensor_ratio(tmp_path: Path, hardware: StandinHardware) -> None:
    settings = load_bench(write_bench(tmp_path, measurement="current", sensor_A_per_A=1000.0, range_A=0.02)).daq
    hardware.sensor_gain = 1000.0  # a closed-loop Hall sensor, 1:1000, into a ±20 mA input
    source = NidaqCurrentSource(settings, lib=hardware.module())
    source.start()
    block = source.read(0.2)
    source.stop()
    assert block is not None and [c.measurement for c in hardware.tasks[0].ai_channels.channels] == ["current"]
    np.testing.assert_allclose(block.current_a, hardware.currents(0, BLOCK), rtol=1e-12)
