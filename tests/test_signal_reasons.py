"""A SIGTERM or SIGHUP that Python could not raise where it landed (a ``__del__``, a weakref or collector callback) is
delivered again by acq (:func:`acq.ui.cli._interrupt_again`); it went to SIGINT's handler, so the recording stopped as
"interrupted by user (Ctrl-C)" — the session file and the printed line named Ctrl-C, not the signal that came. Real
``acq record`` / ``acq monitor`` children, each with one object whose ``__del__`` waits for the signal at a point where
acq's handler raises (before the recorder's or the monitor's own handlers are set)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest

from acq.process_signals import STOP_REASONS
from tests.helpers import seeded_profile
from tests.test_monitor import ROBOT

ROOT = Path(__file__).resolve().parents[1]

#: ``acq ARGV[4:]`` in a child whose ``MODULE.CLASS.METHOD`` (argv[3]) first touches the marker file argv[1] and
#: waits (≤ 60 s) for a stop signal to raise: with argv[2] ``swallowed`` in the ``__del__`` of an object collected
#: there — Python prints nothing of it (acq's unraisable hook takes a KeyboardInterrupt) and the method runs on —,
#: with ``raised`` in the method itself, out of which it goes.
_SWALLOWED_AT = """
import importlib, sys, time
from pathlib import Path
marker, how, where = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
module, cls, method = where.rsplit(".", 2)
owner = getattr(importlib.import_module(module), cls)
original = getattr(owner, method)

def wait_for_the_signal():
    marker.touch()
    end = time.monotonic() + 60
    while time.monotonic() < end:
        time.sleep(0.01)

class SignalLandsHere:
    def __del__(self):
        wait_for_the_signal()

def signalled_first(self, *args, **kwargs):
    if not marker.exists():
        if how == "swallowed":
            SignalLandsHere()  # no reference kept: collected, its __del__ run, at once
        else:
            wait_for_the_signal()
    return original(self, *args, **kwargs)

setattr(owner, method, signalled_first)
sys.argv = ["acq", *sys.argv[4:]]
from acq.entry import main
main()
"""


def _signalled_at(tmp_path: Path, signum: int, how: str, where: str, *args: str) -> tuple[int, list[str]]:
    """Run ``acq ARGS`` with :data:`_SWALLOWED_AT` at ``where`` (``how``: ``swallowed`` or ``raised``), send
    ``signum`` once the child waits there; its exit code and stderr's lines starting ``acq:``."""
    script, marker = tmp_path / "swallowed.py", tmp_path / "in_del"
    script.write_text(_SWALLOWED_AT)
    proc = subprocess.Popen([sys.executable, str(script), str(marker), how, where, *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    end = time.monotonic() + 120
    while not marker.exists():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < end, "the child never reached the point that swallows the signal"
        time.sleep(0.02)
    time.sleep(0.1)  # inside the __del__'s wait
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=120)
    return proc.returncode, [ln for ln in err.replace("\r", "\n").splitlines() if ln.startswith("acq:")]


def _stop_reason(path: Path) -> tuple[str, str]:
    with h5py.File(path, "r") as f:  # the footer strings are fixed-length: h5py reads bytes
        return tuple(bytes(f.attrs[name]).decode().rstrip("\0") for name in ("status", "stop_reason"))  # type: ignore


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_a_swallowed_signal_stops_a_recording_with_its_own_reason(tmp_path: Path, signum: int) -> None:
    """The signal lands in a ``__del__`` as the recording starts (the session file made, the recorder's handlers not
    yet set); delivered again 0.05 s later it stops the recording. Before: status interrupted, reason "interrupted by
    user (Ctrl-C)", and that line printed."""
    out = tmp_path / "sessions"
    code, lines = _signalled_at(
        tmp_path, signum, "swallowed", "acq.recording.recorder.Recorder.run", "record", "--profile", str(seeded_profile(tmp_path)),
        "--duration", "20", "--no-analyze", "--out", str(out))
    (path,) = out.glob("*.h5")
    reason = STOP_REASONS[signum]
    assert (code, _stop_reason(path)) == (130, ("interrupted", reason)), lines
    assert len(lines) == 1 and lines[0].startswith(f"acq: interrupted: {reason} — everything recorded up to the stop "
                                                   f"is kept in {path} ("), lines


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_a_swallowed_signal_stops_a_monitor_with_its_own_reason(tmp_path: Path, signum: int) -> None:
    """The signal lands in a ``__del__`` as the monitor sets its handlers (its folder locked, its catalogue open);
    delivered again it stops the monitor in its first window. Before: "acq: interrupted by user (Ctrl-C): …", the
    window's file stopped with that reason."""
    out = tmp_path / "m"
    code, lines = _signalled_at(
        tmp_path, signum, "swallowed", "acq.monitoring.monitor.Monitor._signals", "monitor", "--bench", str(ROBOT), "--window",
        "10", "--every", "10", "--out", str(out))
    reason = STOP_REASONS[signum]
    assert code == 130, lines
    assert lines[-1].startswith(f"acq: {reason}: ") and "Ctrl-C" not in "".join(lines), lines
    assert [_stop_reason(p) for p in out.glob("*.h5")] in ([], [("interrupted", reason)])


def test_a_signal_before_the_recording_started_names_itself(tmp_path: Path) -> None:
    """A SIGTERM raised as the recording starts (its file made, the recorder's handlers not yet set) finishes the file
    empty. Before: its reason "interrupted by user (Ctrl-C)", and "acq: interrupted before the recording started"."""
    out = tmp_path / "sessions"
    code, lines = _signalled_at(tmp_path, signal.SIGTERM, "raised", "acq.recording.recorder.Recorder.run", "record",
                                "--profile", str(seeded_profile(tmp_path)), "--duration", "20", "--no-analyze",
                                "--out", str(out))
    (path,) = out.glob("*.h5")
    assert (code, _stop_reason(path)) == (130, ("interrupted", "stopped by SIGTERM"))
    assert lines == [f"acq: stopped by SIGTERM before the recording started — nothing recorded ({path}: no samples, "
                     "status interrupted)"]


def test_a_stop_deferred_over_a_block_that_raised_still_reaches_its_handler() -> None:
    # a SIGTERM inside a deferred block (a worker being started) whose body then failed was dropped with the deferring
    # handler: the process went on as if never asked to stop
    from acq.process_signals import signals_deferred

    received: list[int] = []
    before = signal.signal(signal.SIGTERM, lambda signum, frame: received.append(signum))
    try:
        with pytest.raises(ValueError, match="the body failed"):
            with signals_deferred():
                os.kill(os.getpid(), signal.SIGTERM)
                time.sleep(0.01)  # the handler runs between bytecodes: it has run, deferred, by now
                assert received == []
                raise ValueError("the body failed")
        assert received == [signal.SIGTERM]
    finally:
        signal.signal(signal.SIGTERM, before)


def test_a_stop_between_two_restores_still_puts_every_handler_back(monkeypatch: pytest.MonkeyPatch) -> None:
    # where another thread takes a stop signal while signals_deferred puts the handlers back, the first one already
    # put back raises at the next bytecode: the others were left deferring for good, SIGTERM ignored from then on.
    # Here the raise is made to land right after the first handler is put back, as it would.
    from acq import process_signals
    from acq.process_signals import signals_deferred

    def mine(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    before = {s: signal.signal(s, mine) for s in process_signals.STOP_SIGNALS}
    real_signal, restores = signal.signal, []

    def restore_then_stop(signum: int, handler: object) -> object:
        old = real_signal(signum, handler)
        if handler is mine:
            restores.append(signum)
            if len(restores) == 1:
                raise KeyboardInterrupt  # the stop, handled by the handler just put back
        return old

    try:
        with pytest.raises(KeyboardInterrupt):
            with signals_deferred():
                monkeypatch.setattr(process_signals.signal, "signal", restore_then_stop)
        monkeypatch.undo()
        assert set(restores) == set(process_signals.STOP_SIGNALS)  # the first put back twice: raised between
        assert all(signal.getsignal(s) is mine for s in process_signals.STOP_SIGNALS)
    finally:
        monkeypatch.undo()
        for s, handler in before.items():
            signal.signal(s, handler)
