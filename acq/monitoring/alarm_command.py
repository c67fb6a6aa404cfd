"""The ``--on-alarm`` commands of a monitor: started through the shell in the background, reaped, their failures told.

``sh -c`` as cron, systemd and git hooks do: pipes, redirections and ``$ACQ_K`` work; the values reach the command
only as environment variables, never in its text. The monitor does not wait for it — a slow mail or webhook must not
stop the capture — and at its end gives all commands still running one shared wait, then leaves them running (they may
be mid-send).
"""

from __future__ import annotations

import subprocess
import time
from collections.abc import Callable, Mapping

from acq.environment import user_environment

#: How long the ending monitor waits for an alarm command still running (a mail or a webhook takes seconds).
ALARM_WAIT_S = 30.0
#: The exit codes POSIX shells give themselves (XCU 2.8.2): the command was not found / could not be executed.
_SHELL_EXITS = {127: "command not found", 126: "not executable"}


class AlarmCommands:
    """The alarm commands started and not yet reaped.

    Parameters
    ----------
    command : str or None
        The ``--on-alarm`` command (None: nothing is run).
    on_problem : callable
        Told each problem in one line ("alarm command failed: exit 127 (command not found)").
    """

    def __init__(self, command: str | None, on_problem: Callable[[str], None]) -> None:
        self.command = command
        self._on_problem = on_problem
        self._running: list[subprocess.Popen[bytes]] = []

    def start(self, values: Mapping[str, str]) -> None:
        """Start the command with ``values`` (``ACQ_K`` …) added to the user's environment; do not wait for it."""
        if not self.command:
            return
        try:
            # a session of its own: the Ctrl-C that stops the monitor must not kill a mail or webhook mid-send
            self._running.append(subprocess.Popen(["/bin/sh", "-c", self.command], env={**user_environment(), **values},
                                                  stdin=subprocess.DEVNULL, start_new_session=True))
        except OSError as e:
            self._failed(f"cannot start /bin/sh: {e.strerror or e}")
        self.reap(wait=False)

    def reap(self, wait: bool) -> None:
        """Collect the commands that ended and report those that failed; with ``wait`` (the monitor ends) give them
        together up to :data:`ALARM_WAIT_S` and report one still running (it is left running: it may be mid-send)."""
        deadline = time.monotonic() + ALARM_WAIT_S  # one for all: N slow commands must not hold the exit N × 30 s
        for proc in list(self._running):
            if wait:
                try:
                    proc.wait(timeout=max(0.0, deadline - time.monotonic()))
                except subprocess.TimeoutExpired:
                    self._on_problem(f"alarm command still running after {ALARM_WAIT_S:g} s when the monitor "
                                     f"ended (pid {proc.pid}, left running)")
                    self._running.remove(proc)
                    continue
            code = proc.poll()
            if code is None:
                continue
            self._running.remove(proc)
            if code > 0:
                self._failed(f"exit {code}" + (f" ({_SHELL_EXITS[code]})" if code in _SHELL_EXITS else ""))
            elif code < 0:
                self._failed(f"killed by signal {-code}")

    def _failed(self, why: str) -> None:
        self._on_problem(f"alarm command failed: {why}")
