"""Child processes that end with the process that started them."""

from __future__ import annotations

import ctypes
import os
import signal
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
