"""Signals held while a few renames run, delivered after them: outputs replaced all or none."""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager

HELD_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


@contextmanager
def signals_held():
    """SIGINT, SIGTERM and SIGHUP held while the block runs and delivered after it (each once), so that a few
    renames are done all or none. Python runs signal handlers in the main thread only, whichever thread the
    kernel chose: its handlers are swapped there, not the thread's signal mask. Elsewhere, and for a signal
    ignored, nothing is held."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list = []
    held: dict = {}
    try:
        for s in HELD_SIGNALS:
            if signal.getsignal(s) not in (signal.SIG_IGN, None):
                held[s] = signal.signal(s, lambda signum, frame: caught.append(signum))
    except BaseException:  # a signal come before the block: its handler ran as a swap began, nothing is done yet
        _put_back(held)
        raise
    try:
        yield
    finally:
        late = _put_back(held)
        for s in dict.fromkeys(caught):
            try:
                signal.raise_signal(s)
            except BaseException as exc:  # the handler raised at once: its exception, once all are delivered
                late = late or exc
        if late is not None:
            raise late


def _put_back(handlers: dict):
    """Every handler of ``handlers`` put back; the exception a signal's handler raised meanwhile (signal.signal
    runs a pending one before it swaps, and raises its exception without swapping: so each is tried again)."""
    late = None
    for s, handler in handlers.items():
        while True:
            try:
                signal.signal(s, handler)
                break
            except BaseException as exc:
                late = late or exc
    return late
