"""A progress line on stderr when it is a terminal; silent otherwise (logs, CI, pipes)."""

from __future__ import annotations

import os
import sys
import time


class Progress:
    def __init__(self, label: str, total: int, stream=None, min_interval: float = 0.1):
        self.label, self.total = label, max(int(total), 1)
        self.stream = stream or sys.stderr
        self.enabled = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.start = time.monotonic()
        self.last = -float("inf")  # the first update shows at once: what a long first step is doing
        self.min_interval = min_interval
        self.done = 0

    def update(self, step: int = 1, note: str = "") -> None:
        self.done += step
        now = time.monotonic()
        if not self.enabled or (now - self.last < self.min_interval and self.done < self.total):
            return
        self.last = now
        frac = min(self.done / self.total, 1.0)
        bar = "#" * int(frac * 24)
        self._show(f"{self.label} [{bar:<24}] {self.done}/{self.total} {now - self.start:5.1f}s {note}")

    def _show(self, line: str) -> None:
        """``line`` over the last, cut and padded to the terminal's width: a line that wraps is redrawn below
        itself, and spaces erase where an escape (``TERM=dumb``) would not."""
        width = self._width() - 1  # the last column: a full line wraps on some terminals
        self.stream.write("\r" + line[:width].ljust(width))
        self.stream.flush()

    def _width(self) -> int:
        """COLUMNS where set (as shutil.get_terminal_size reads it), else the terminal's, else 80."""
        try:
            return max(int(os.environ["COLUMNS"]), 2)
        except (KeyError, ValueError):
            pass
        try:
            columns = os.get_terminal_size(self.stream.fileno()).columns
            return max(columns, 2) if columns else 80  # 0: a serial console's tty that was never sized
        except (OSError, ValueError, AttributeError):  # not a real terminal after all
            return 80

    def grow(self, steps: int, note: str = "") -> None:
        """More work than the total said (a fit taken again): ``steps`` more, shown with ``note``."""
        self.total += max(int(steps), 0)
        self.update(0, note)

    def per_item(self, note):
        """A callback ``(item, *more)`` for work done one item after another: the bar moves one as
        each item after the first begins, and shows ``note(item, *more)``."""
        current = []

        def callback(item, *more):
            if current != [item]:
                if current:
                    self.update()
                current[:] = [item]
            self.update(0, note(item, *more))

        return callback

    def close(self) -> None:
        if self.enabled:
            self._show("")
            self.stream.write("\r")
            self.stream.flush()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def shown_while(label: str, note: str, work):
    """``work()``'s result, a one-step bar saying ``note`` while it runs: a step of seconds (a large file read or
    written) seen on a terminal, not a silence."""
    with Progress(label, 1) as bar:
        bar.update(0, note)
        return work()
