"""What the benchmark scripts share: a progress log with elapsed time, number formats, markdown tables.

The scripts run as ``python bench/NAME.py``, so this folder is on their path: ``from benchutil import ...``.
"""

from __future__ import annotations

import sys
import time

import numpy as np

START = time.monotonic()


def log(msg: str) -> None:
    """A progress line on stderr, with the seconds since the script started."""
    print(f"[{time.monotonic() - START:6.1f}s] {msg}", file=sys.stderr, flush=True)


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
