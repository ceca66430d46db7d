"""Rows of 128 samples when the reading noise does not average down: what flicker (1/f) noise does to identify at 16
and at 128 samples per row, and whether `tactile-host noise` tells the user beforehand.

calibration.md advises 128 samples per row where the noise averages down as white noise, and keeps 16 as the default
until a real unit shows it does. This bench asks what happens where it does not. The units, the schedule and the
capture are bench/units.py's headline (40 D-optimal poses scheduled for the row's noise, 0.01 mm rig, magpylib's
readings, an exact zero); units: part 3's first fresh set of bench/identify_bound.py (seeds 101-120). Each row's
noise is made sample by sample in time: white noise (the sensor's 0.5 mV rms per sample) plus flicker
(host.simsensor.Flicker: 1/f noise whose Allan deviation is the level given, from 0.3 s to 100 s), samples at the
two ADS1115s' 140 per second, rows a capture's row cycle on a printer apart (bench/units.py's timing: the move, the
settle, the reading). identify takes the noise the capture records (host.capture.NoiseStats: the samples' spread
over sqrt(S), pooled over rows), as fitgen identify does from the capture's meta.

Per flicker level and samples per row: how many captures identify refuses (reduced chi-square over 3), the reduced
chi-square (median, greatest), issue 21's identification line on the set (the medians it reads, coverage) and the
errors over their standard errors (rms; 1 for a posterior as wide as its errors); then, per flicker level, what
`tactile-host noise` reads from a 120 s rest recording of each unit's noise (host.allan: the worst element's ratio
of a row's real noise to the recorded, median over units, and the samples per row it recommends).

    python bench/noise_averaging.py          # about 5 minutes on 2 cores
    python bench/noise_averaging.py --plot docs/img
"""

from __future__ import annotations

import sys
from collections import Counter
from multiprocessing import get_context
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from benchutil import fmt, log, parser, table  # noqa: E402
from fitgen.base.errors import InputError  # noqa: E402
from fitgen.fitting.identify import CHI2_LIMIT, derived_at, identify  # noqa: E402
from fitgen.fitting.schedule import schedule  # noqa: E402
from fitgen.fitting.verdict import check_explained  # noqa: E402
from fitgen.physics.simulate import rig_poses  # noqa: E402
from host.allan import CANDIDATES, averaging  # noqa: E402
from host.noiserun import SECONDS  # noqa: E402
from host.simsensor import Flicker  # noqa: E402

import units as U  # noqa: E402

FLICKER = (0.0, 0.01e-3, 0.025e-3, 0.05e-3)  # V: the Allan deviation's floor; the white noise is 0.5 mV per sample
TOLD = "told"  # the samples per row tactile-host noise recommends for the unit's noise
SAMPLES = (16, 128, TOLD)
SEEDS = tuple(range(101, 121))
RIG = U.HEAD[1]
N_POSES = U.HEAD[0]
LIMIT_MM, LIMIT_REL, COVER = U.OFFSET_MM, U.SENS_REL, U.COVER
CTX = None


def noise_stream(n_rows: int, samples: int, cycle: float, level: float, sigma: float, rng) -> np.ndarray:
    """(rows, samples, 8) noise: white ``sigma`` per sample plus flicker ``level``, samples SAMPLE_S apart,
    rows ``cycle`` seconds apart."""
    t = (np.arange(n_rows)[:, None] * cycle + np.arange(samples)[None, :] * U.SAMPLE_S).ravel()
    white = rng.normal(0.0, sigma, (t.size, 8))
    if level > 0:
        f = Flicker(level, 8, np.random.default_rng(rng.integers(2 ** 63)))
        white += np.array([f.at(s) for s in t])  # the process steps through time, sample after sample
    return white.reshape(n_rows, samples, 8)


def rest_check(level: float, seed: int) -> dict:
    """What tactile-host noise reads of a unit's noise: SECONDS at rest, its own draws."""
    n = int(SECONDS / U.SAMPLE_S)
    rest = noise_stream(1, n, 0.0, level, CTX["sigma"], np.random.default_rng([seed, 7]))[0]
    av = averaging(rest, 1.0 / U.SAMPLE_S)
    return {"ratio": dict(zip(av.candidates, av.worst)), "recommended": av.recommended()}


def task(spec):
    level, asked, seed = spec
    out = {"spec": spec}
    if asked == TOLD:
        out["noise"] = rest_check(level, seed)
        samples = out["noise"]["recommended"] or CANDIDATES[0]  # none within the limit: the smallest, 16
    else:
        samples = asked
    out["samples"] = samples
    labels = CTX["labels"][samples]
    unit, theta = U.draw_unit(CTX["drawing"], seed)
    rng = np.random.default_rng([seed, samples, int(round(level * 1e7))])
    true = rig_poses(labels, RIG, np.random.default_rng([seed, N_POSES, 3]))
    noise = noise_stream(len(labels), samples, CTX["base"] + samples * U.SAMPLE_S, level, CTX["sigma"], rng)
    y = U.magpylib_readings(unit, true) + noise.mean(axis=1)
    recorded = np.sqrt(np.mean(noise.var(axis=1, ddof=1) / samples, axis=0))  # as host.capture.NoiseStats
    try:
        ident = identify(CTX["drawing"], y, labels, recorded, rig_error=RIG, zero_error=0.0)
        check_explained(ident, f"unit {seed}'s capture", U.PRESET, "the bench's")  # as fitgen identify refuses
    except InputError as exc:
        return {**out, "error": str(exc).splitlines()[0]}
    truth = derived_at(ident.space, theta)
    e, s, _ = U.derived_errors({"derived": ident.derived(), "derived_truth": truth})
    return {**out, "chi2": ident.reduced_chi2, "err": np.abs(e), "se": s}


def _init(ctx):
    global CTX
    CTX = ctx


def main() -> None:
    global FLICKER, SAMPLES
    ap = parser(__doc__)
    ap.add_argument("--units", type=int, default=len(SEEDS), help=f"units (default {len(SEEDS)}: seeds 101 on)")
    ap.add_argument("--flicker", help="flicker levels, mV, comma-separated (default "
                    f"{','.join(f'{1e3 * f:g}' for f in FLICKER)})")
    ap.add_argument("--samples", help="samples per row, comma-separated, 'told' among them (default 16,128,told)")
    ap.add_argument("--plot", metavar="FOLDER", help="also FOLDER/noise_averaging.png")
    args = ap.parse_args()
    drawing = U.load_sensor(U.PRESET).with_transfer(U.TRANSFER)
    sigma = drawing.noise
    labels = {s: schedule(drawing, N_POSES, noise=sigma / np.sqrt(s), rig_error=RIG, zero_error=0.0)[0]
              for s in CANDIDATES}
    base = U.capture_time(labels[U.SAMPLES]) / N_POSES - U.SAMPLES * U.SAMPLE_S  # move and settle, per row
    ctx = {"drawing": drawing, "sigma": sigma, "labels": labels, "base": base}
    if args.flicker:
        FLICKER = tuple(1e-3 * float(v) for v in args.flicker.split(","))
    if args.samples:
        SAMPLES = tuple(v if v == TOLD else int(v) for v in args.samples.split(","))
    seeds = tuple(range(SEEDS[0], SEEDS[0] + args.units))
    specs = [(f, s, seed) for f in FLICKER for s in SAMPLES for seed in seeds]
    log(f"{len(specs)} captures identified on 2 processes")
    results = []
    with get_context("fork").Pool(2, initializer=_init, initargs=(ctx,)) as pool:
        for i, r in enumerate(pool.imap(task, specs), 1):
            results.append(r)
            if i % len(seeds) == 0:
                log(f"{i} of {len(specs)}")
    rows, noise_rows, fig = [], [], {}
    for f in FLICKER:
        for s in SAMPLES:
            rs = [r for r in results if r["spec"][:2] == (f, s)]
            ok = [r for r in rs if "error" not in r]
            chi2 = np.array([r["chi2"] for r in ok])
            err, se = np.array([r["err"] for r in ok]), np.array([r["se"] for r in ok])
            off = np.median(err[:, :3], axis=0).max()
            worst = np.median(err[:, 3:].max(axis=1))
            cover = float(np.mean(err <= se))
            meets = off <= LIMIT_MM and worst <= LIMIT_REL and COVER[0] <= cover <= COVER[1] and len(ok) == len(rs)
            z = float(np.sqrt(np.mean((err / se) ** 2)))
            fig[(f, s)] = (z, float(np.median(chi2)), float(np.median(err[:, 2])))
            used = Counter(r["samples"] for r in rs).most_common()
            told = s if s != TOLD else "told: " + ", ".join(f"{k} ({v})" for k, v in used)
            # flicker's variance over a row's white noise variance: what tactile-host noise reads, less its error
            share = "-" if s == TOLD else f"{f ** 2 * s / sigma ** 2:.2g}"
            rows.append([f"{1e3 * f:g}", str(told), share, f"{len(rs) - len(ok)} of {len(rs)}",
                         f"{np.median(chi2):.2f} ({chi2.max():.2f})", fmt(np.median(err[:, 2])), fmt(off),
                         f"{100 * worst:.2g} %", f"{100 * cover:.0f} %", f"{z:.2f}", "yes" if meets else "no"])
        recs = [r["noise"] for r in results if r["spec"][:2] == (f, TOLD)]
        if not recs:
            continue
        ratio = {s: np.median([n["ratio"][s] for n in recs]) for s in (16, 128)}
        told = Counter(str(n["recommended"]) for n in recs).most_common()
        noise_rows.append([f"{1e3 * f:g}", f"{ratio[16]:.2f}", f"{ratio[128]:.2f}",
                           ", ".join(f"{k} ({v} units)" for k, v in told)])
    print(f"paper in {U.TRANSFER}, {len(seeds)} units (seeds {seeds[0]}-{seeds[-1]}), {N_POSES} D-optimal poses "
          f"scheduled for the row's noise, rig {RIG} mm, white noise {1e3 * sigma:g} mV per sample, samples "
          f"{1 / U.SAMPLE_S:.0f} per s; a row cycle on a printer {base + 16 * U.SAMPLE_S:.2f} s at 16 samples, "
          f"{base + 128 * U.SAMPLE_S:.2f} s at 128; `told`: each unit at the samples per row tactile-host noise "
          "recommends for its noise (the number of units at each in brackets). identify refuses above a reduced "
          f"chi-square of {CHI2_LIMIT:g}. The line: "
          f"every offset's median within {LIMIT_MM} mm, the median unit's worst element within "
          f"{100 * LIMIT_REL:g} %, coverage {100 * COVER[0]:.0f}-{100 * COVER[1]:.0f} %, no capture refused.\n")
    print(table(["flicker [mV]", "samples per row", "flicker share", "refused", "reduced chi-square, median (greatest)",
                 "offset z [mm]", "offset, worst axis [mm]", "sensitivity, worst element", "coverage",
                 "error / standard error, rms", "meets the line"], rows))
    if noise_rows:  # only `told` records a recording
        print(f"\nWhat `tactile-host noise` reads from {SECONDS:g} s at rest (per unit its own noise draws; the "
              "worst element's ratio of a row's real noise to what the capture records, median over units):\n")
        print(table(["flicker [mV]", "ratio at 16", "ratio at 128", "samples per row it recommends"], noise_rows))
    if args.plot and TOLD in SAMPLES:
        _plot(fig, Path(args.plot))


def _plot(fig, folder: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fitgen.base.fileio import write_in_folder

    f_mv = [1e3 * f for f in FLICKER]
    p, (c, a, b) = plt.subplots(1, 3, figsize=(13, 3.8))
    # `told` is 16 for every unit at the two higher floors: drawn dashed, hollow and larger over 16's line, or it
    # hid it
    style = {16: dict(marker="o"), 128: dict(marker="s"), TOLD: dict(marker="^", ls="--", mfc="none", ms=10)}
    for s in SAMPLES:
        name = f"{s} samples per row" if s != TOLD else "as tactile-host noise tells"
        for ax, k in ((c, 2), (a, 1), (b, 0)):
            ax.plot(f_mv, [fig[(f, s)][k] for f in FLICKER], label=name, **style.get(s, {}))
    c.axhline(LIMIT_MM, color="k", ls=":", lw=0.9, label=f"the line: {LIMIT_MM:g} mm")
    c.set_ylabel("magnet's height: |error| [mm], median unit")
    a.axhline(CHI2_LIMIT, color="k", ls=":", lw=0.9, label=f"identify refuses above {CHI2_LIMIT:g}")
    a.set_ylabel("reduced chi-square, median unit")
    b.axhline(1.0, color="k", ls=":", lw=0.9, label="1: the standard errors right")
    b.set_ylabel("error / standard error, rms")
    for ax in (c, a, b):
        ax.set_xlabel("flicker floor [mV] (white noise: 0.5 per sample)")
        ax.grid(True, lw=0.3, alpha=0.5)
        ax.legend(fontsize=8)
    p.tight_layout()
    import io

    buf = io.BytesIO()
    p.savefig(buf, format="png", dpi=110, metadata={"Software": None})
    print(f"wrote {write_in_folder(folder, 'noise_averaging.png', buf.getvalue())}", file=sys.stderr)


if __name__ == "__main__":
    main()
