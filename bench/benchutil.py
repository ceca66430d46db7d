"""What the benchmark scripts share: a progress log with elapsed time, number formats, markdown tables, the
command line's parser and the check for the tools a bench runs.

The scripts run as ``python bench/NAME.py``, so this folder is on their path: ``from benchutil import ...``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time

import numpy as np

START = time.monotonic()


def log(msg: str) -> None:
    """A progress line on stderr, with the seconds since the script started."""
    print(f"[{time.monotonic() - START:6.1f}s] {msg}", file=sys.stderr, flush=True)


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose refusal is one line: a bench's usage is what --help prints, and a bad option
    should not look like the start of a run's output."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n")


def parser(doc: str) -> argparse.ArgumentParser:
    """The parser of a bench whose docstring is ``doc``: --help gives its first paragraph (one sentence in
    every bench), a bad option or value one line ``NAME.py: error: ...`` on stderr and exit 2."""
    return _Parser(description=" ".join(doc.strip().split("\n\n")[0].split()))


def parse_args(doc: str, add=None, argv: list[str] | None = None) -> argparse.Namespace:
    """parser(doc), given its options by ``add(parser)`` if any, applied to ``argv`` (default sys.argv[1:]).
    A bench without options calls it too, so that an option it does not know is refused rather than ignored."""
    ap = parser(doc)
    if add is not None:
        add(ap)
    return ap.parse_args(argv)


# The Debian/Ubuntu packages that bring each tool a bench runs, for the line that says how to install one
APT = {"gcc": "gcc", "valgrind": "valgrind", "objdump": "binutils", "Rscript": "r-base-core",
       "pkg-config": "pkg-config", "avr-gcc": "gcc-avr avr-libc", "avr-size": "binutils-avr",
       "avr-nm": "binutils-avr", "simavr": "simavr libsimavr-dev libelf-dev",
       "qemu-system-arm": "qemu-system-arm", "qemu-arm": "qemu-user",
       "arm-none-eabi-gcc": "gcc-arm-none-eabi libnewlib-arm-none-eabi",
       "arm-none-eabi-size": "binutils-arm-none-eabi", "arm-none-eabi-nm": "binutils-arm-none-eabi",
       "arm-linux-gnueabihf-gcc": "gcc-arm-linux-gnueabihf"}


def need_tools(*tools: str, libs: tuple[str, ...] = ()) -> None:
    """Exit 2 with one line naming what is missing and how to install it, unless every program in ``tools``
    is on PATH and every library in ``libs`` is known to pkg-config. Called before the first minute of work,
    so that a missing tool is not found by a traceback halfway through."""
    if libs and "pkg-config" not in tools:
        tools += ("pkg-config",)
    missing = [t for t in tools if shutil.which(t) is None]
    if not missing:
        missing = [lib for lib in libs
                   if subprocess.run(["pkg-config", "--exists", lib], capture_output=True).returncode != 0]
    if missing:
        packages = " ".join(dict.fromkeys(p for t in missing for p in APT.get(t, t).split()))
        what = ", ".join(t + (" (library, pkg-config)" if t in libs else "") for t in missing)
        print(f"{os.path.basename(sys.argv[0])}: {what} not found; install with: sudo apt-get install {packages}",
              file=sys.stderr)
        sys.exit(2)


def fmt(x) -> str:
    """3 significant digits; '-' for None, 'inf' for a non-finite or huge value."""
    if x is None:
        return "-"
    x = float(x)
    if not np.isfinite(x) or x > 1e6:
        return "inf"
    return f"{x:.3g}"


def table(head: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(head) + " |", "| " + " | ".join("---" for _ in head) + " |"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def stats(err: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(max |e|, RMS e) per column."""
    return np.abs(err).max(axis=0), np.sqrt(np.mean(err * err, axis=0))


def cramer_rao_floor(sensor, poses: np.ndarray) -> dict:
    """The Cramer-Rao bounds (fitgen.physics.observe.cramer_rao, the sensor's noise, all five components) at each pose:
    RMS over the poses, median, how many are infinite, and the RMS over the finite ones."""
    from fitgen.physics.observe import cramer_rao

    b = cramer_rao(sensor, poses, sensor.noise)
    finite = np.where(np.isfinite(b), b, np.nan)
    with np.errstate(over="ignore", invalid="ignore"):
        return {"rms": np.sqrt(np.mean(b * b, axis=0)), "median": np.median(b, axis=0),
                "inf": np.isinf(b).sum(axis=0), "finite_rms": np.sqrt(np.nanmean(finite * finite, axis=0))}


def unbiased_maxima(bounds: np.ndarray, draws: int, rng: np.random.Generator, trials: int = 200) -> np.ndarray:
    """Per trial, the max |error| per column of an unbiased estimator at the Cramer-Rao ``bounds`` (P, C) over
    ``draws`` noisy readings of each pose: Gaussian errors of those standard deviations. Shape (trials, C)."""
    return np.array([np.abs(rng.standard_normal((draws,) + bounds.shape) * bounds).reshape(-1, bounds.shape[1])
                     .max(axis=0) for _ in range(trials)])
