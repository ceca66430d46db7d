"""Benchmark: element readings with fitgen's cylinder kernel versus magpylib, side by side.

Run:  python bench/field.py [--repeats N] [--large-repeats N] [--large N]

Two cases on the ``paper`` sensor (8 radial elements): the paper's simulation grid
(1,875 poses) and a large seeded random batch (200,000 poses). Each is computed by

* fitgen:   ``fitgen.physics.pose.field_readings(sensor, poses)``
* magpylib: one ``Cylinder`` whose path holds every pose (positions and scipy
  orientations), a ``Sensor`` with 8 pixels at the element positions, ``getB``,
  then B . axis_k -- the same work, done the way magpylib is meant to be used.

Both sides are timed end to end from the (P, 5) pose array to the (P, 8) readings
(rotations included). The two results are checked to agree to 1e-6 of the largest
reading. Each measurement is repeated and the median is reported; peak memory is
measured in a separate, untimed run with tracemalloc (numpy reports its buffers to
it). Prints a markdown table on stdout, progress on stderr.
"""

from __future__ import annotations

import os
import platform
import statistics
import sys
import time
import tracemalloc

import numpy as np

import magpylib as magpy
from scipy.spatial.transform import Rotation

from benchutil import parser
from fitgen.physics.pose import field_readings
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses

SEED = 2024
RANGES = {"dx": (-2.0, 2.0), "dy": (-2.0, 2.0), "dz": (-3.0, 0.0), "thx": (-10.0, 10.0), "thy": (-10.0, 10.0)}


def progress(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def random_poses(n: int, seed: int = SEED) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(lo, hi, n) for lo, hi in RANGES.values()])


def fitgen_readings(sensor, poses: np.ndarray) -> np.ndarray:
    return field_readings(sensor, poses)


def magpylib_readings(sensor, poses: np.ndarray) -> np.ndarray:
    mag = sensor.magnet
    cyl = magpy.magnet.Cylinder(
        dimension=(mag.diameter, mag.height),
        polarization=(0.0, 0.0, mag.polarization),  # T
        position=np.asarray(mag.rest_center) + poses[:, :3],
        orientation=Rotation.from_euler("xy", poses[:, 3:5], degrees=True),
    )
    pixels = magpy.Sensor(pixel=sensor.positions)
    B = cyl.getB(pixels)  # (P, N, 3) in T
    return np.einsum("pnj,nj->pn", B, sensor.axes) * 1e3  # mT


def run_once(fn, sensor, poses) -> float:
    t0 = time.perf_counter()
    fn(sensor, poses)
    return time.perf_counter() - t0


def peak_memory(fn, sensor, poses) -> float:
    """Peak traced allocation (MiB) during one call."""
    tracemalloc.start()
    tracemalloc.reset_peak()
    fn(sensor, poses)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak / 2**20


def main(argv=None) -> None:
    ap = parser(__doc__)
    ap.add_argument("--repeats", type=int, default=5, help="timed runs for the paper grid (default 5)")
    ap.add_argument("--large-repeats", type=int, default=5, help="timed runs for the large batch (default 5, >= 3)")
    ap.add_argument("--large", type=int, default=200_000, help="poses in the large random batch (default 200000)")
    args = ap.parse_args(argv)
    if args.repeats < 1 or args.large_repeats < 3 or args.large < 1:
        ap.error("--repeats must be >= 1, --large-repeats >= 3, --large >= 1")

    sensor = load_sensor("paper")
    n_el = sensor.n_elements
    cases = [
        ("paper grid (paper-sim)", grid_poses(PAPER_GRIDS["paper-sim"]), args.repeats),
        (f"random, seed {SEED}", random_poses(args.large), args.large_repeats),
    ]
    impls = [("fitgen", fitgen_readings), ("magpylib", magpylib_readings)]

    rows = []
    t_start = time.perf_counter()
    for name, poses, repeats in cases:
        progress(f"{name}: {len(poses):,} poses x {n_el} elements")
        # warm-up (also the agreement check), then the timed runs, then memory
        out = {label: fn(sensor, poses) for label, fn in impls}
        scale = np.abs(out["magpylib"]).max()
        dev = np.abs(out["fitgen"] - out["magpylib"]).max()
        rel = dev / scale
        if not rel <= 1e-6:
            raise SystemExit(f"{name}: fitgen and magpylib disagree: max |diff| = {dev:.3e} mT ({rel:.2e} of max)")
        res = {}
        progress(f"  agree: max |diff| {dev:.2e} mT ({rel:.1e} of the largest reading)")
        # interleave the two implementations so that machine noise hits both alike
        times = {label: [] for label, _ in impls}
        for i in range(repeats):
            for label, fn in impls:
                times[label].append(run_once(fn, sensor, poses))
                progress(f"  {label}: run {i + 1}/{repeats} {times[label][-1]:.3f} s")
        for label, fn in impls:
            med = statistics.median(times[label])
            res[label] = {"median": med, "min": min(times[label]), "max": max(times[label]),
                          "rate": len(poses) * n_el / med, "mem": peak_memory(fn, sensor, poses)}
        rows.append((name, len(poses), repeats, res, dev, rel))
    total = time.perf_counter() - t_start

    print(f"Element readings of the `paper` sensor ({n_el} elements): fitgen vs magpylib {magpy.__version__}\n")
    print("| case | poses | readings | impl | runs | median s | (min-max s) | readings/s | peak MiB "
          "| speed fitgen/magpylib | max abs diff (mT) |")
    print("|---|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|")
    for name, n, repeats, res, dev, rel in rows:
        ratio = res["magpylib"]["median"] / res["fitgen"]["median"]
        for label in ("fitgen", "magpylib"):
            r = res[label]
            print(f"| {name} | {n:,} | {n * n_el:,} | {label} | {repeats} | {r['median']:.4f} "
                  f"| {r['min']:.4f}-{r['max']:.4f} | {r['rate']:,.0f} | {r['mem']:.0f} "
                  f"| {f'{ratio:.2f}x' if label == 'fitgen' else ''} "
                  f"| {f'{dev:.1e} ({rel:.0e} of max)' if label == 'fitgen' else ''} |")
    print()
    print(f"Machine: {platform.machine()}, {os.cpu_count()} CPUs (shared, noisy), Python "
          f"{platform.python_version()}, numpy {np.__version__}, magpylib {magpy.__version__}. "
          f"Medians of interleaved runs; total {total:.0f} s.")
    large = rows[-1][3]
    fast = large["fitgen"]["median"] <= large["magpylib"]["median"]
    rate = large["fitgen"]["rate"] >= 1e6
    print(f"Target (>= magpylib speed at {rows[-1][1]:,} poses, >= 1e6 readings/s): "
          f"{'met' if fast and rate else 'NOT met'} (speed ratio {large['magpylib']['median'] / large['fitgen']['median']:.2f}x, "
          f"{large['fitgen']['rate']:,.0f} readings/s).")


if __name__ == "__main__":
    main()
