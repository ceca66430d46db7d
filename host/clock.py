"""Clocks the drivers, the simulated bus and the readout loop share.

``RealClock`` is the wall clock. ``VirtualClock`` only moves when something sleeps
on it (the drivers' waits, the simulated bus's transfer times): tests and the
benchmark run an 8 SPS converter in no real time, and the bus's own timing model
gives the rates a real setup would reach.
"""

from __future__ import annotations

import time


class RealClock:
    monotonic = staticmethod(time.monotonic)
    time = staticmethod(time.time)

    @staticmethod
    def sleep(seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)


class VirtualClock:
    def __init__(self, start: float = 0.0, epoch: float = 1_700_000_000.0):
        self.t = float(start)
        self.epoch = epoch

    def monotonic(self) -> float:
        return self.t

    def time(self) -> float:
        return self.epoch + self.t

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            self.t += seconds


REAL_CLOCK = RealClock()
