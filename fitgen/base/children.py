"""Child processes that end with the process that started them."""

from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import sys

PR_SET_PDEATHSIG = 1  # linux/prctl.h


def _prctl():
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None


_PRCTL = _prctl()


def tied(then=None):
    """A ``preexec_fn`` for subprocess.Popen: the child gets SIGTERM when the thread that started it ends, however
    it ends (a SIGKILL leaves no chance to stop an emulator, which would hold its port and files); on Linux, elsewhere
    nothing. ``then()``: more set-up in the child."""
    parent = os.getpid()

    def preexec():
        if _PRCTL is not None:
            _PRCTL(PR_SET_PDEATHSIG, signal.SIGTERM)
            if os.getppid() != parent:  # the parent died before the signal was asked for
                os._exit(1)
        if then is not None:
            then()

    return preexec


GRACE_S = 2.0  # how long an interrupted tool has to clean up (a compiler its temporary files) before SIGKILL


def run_captured(cmd: list[str], input: str | None = None, timeout: float | None = None,
                 **popen) -> subprocess.CompletedProcess:
    """``subprocess.run(cmd, input=input, timeout=timeout, capture_output=True, text=True)``, but the tool runs in
    a session of its own and, when this process is interrupted (Ctrl-C, SIGTERM, SIGHUP) or the timeout passes,
    it and the processes it started get SIGTERM and GRACE_S seconds to clean up before SIGKILL. subprocess.run
    sends SIGKILL at once, which leaves gcc's temporary files in $TMPDIR; and in a session of its own the tool
    takes no terminal Ctrl-C meant for this process, which ends it here instead. The exception is raised again."""
    with subprocess.Popen(cmd, stdin=subprocess.PIPE if input is not None else None, stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, text=True, start_new_session=True, **popen) as proc:
        try:
            out, err = proc.communicate(input, timeout=timeout)
        except BaseException:
            _end_group(proc)
            raise
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def _end_group(proc: subprocess.Popen) -> None:
    """SIGTERM to ``proc``'s process group, SIGKILL after GRACE_S if it still runs, whatever interrupts the wait."""
    try:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(GRACE_S)
    except (ProcessLookupError, subprocess.TimeoutExpired):
        pass
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)  # the group: a compiler's cc1 and as outlive the driver otherwise
        except ProcessLookupError:
            pass
