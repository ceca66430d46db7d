"""The default fit's noise rows folded as their Gram matrix against the QR fold of the stacked rows.

Run: ``python bench/noise_fold.py > /tmp/noisefold.md`` (about 1-2 minutes on 2 cores; progress on stderr). On 20,000
random poses of the paper sensor (noise-free, seed 1, as ``fitgen simulate --random 20000 --seed 1``),
the harmonics family's dz (252 candidates) and thy (279, with d-terms from the stage-1 fit), noise
0.0005 rms: the triangle of [data rows; rounding rows; noise rows] with the noise rows folded by QR
(stepwise.compress over augment.noise_blocks, the way before issue 20) and as their Gram matrix
(augment.noise_gram), side by side: the time of the fold, the column-scaled singular values of the
QR triangle, the Gram fold's relative error in |A x|^2 along each of those singular directions, and
whether the search chooses alike. With ``--precision exact`` (no rounding rows), the case the fit
still folds by QR (augment.gram_fold), for comparison.

Timing: after one untimed round, ``--rounds`` rounds (default 9), each timing the QR fold and then the Gram
fold, so that a change in a shared machine's load falls on both sides alike (timed all QR folds first, then all
Gram folds, the speed-ups read 2.0x and 2.8x in one run, 3.3x and 3.9x in another). The table gives each fold's
median time, and the median and the range over the rounds of their ratio: the range is how far one round's
load can move it.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from benchutil import log, parser
from fitgen.fitting.augment import ROUNDING_FACTOR, UNIT_ROUNDOFF, noise_blocks, noise_gram, rounding_rows
from fitgen.fitting.fit import FitSettings, _d_jacobian, fit_model, ring_harmonics
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import DEFAULT_RANGES, pose_rng, random_poses, simulate
from fitgen.fitting.stepwise import compress, stepwise
from fitgen.equations.terms import Term, candidate_terms, design_matrix

ROWS, SEED = 20_000, 1


def main() -> None:
    ap = parser(__doc__)
    ap.add_argument("--precision", choices=("float", "exact"), default="float",
                    help="float: with the float rounding rows, as the default fit (default); exact: none")
    ap.add_argument("--rounds", type=int, default=9, help="timing rounds, each QR then Gram (default 9)")
    args = ap.parse_args()
    if args.rounds < 1:
        ap.error("--rounds must be >= 1")
    exact = args.precision == "exact"
    u = 0.0 if exact else ROUNDING_FACTOR * UNIT_ROUNDOFF["float"]
    sensor = load_sensor("paper")
    ds = simulate(sensor, random_poses(ROWS, DEFAULT_RANGES, pose_rng(SEED)))
    v, sigma, harmonics = ds.inputs, sensor.noise, ring_harmonics(ds, sensor)
    stage1 = fit_model(ds, ("dx", "dy", "dz"), FitSettings.family("harmonics"), sensor=sensor)
    d, d_jac = stage1.predict(v), _d_jacobian(stage1.equations, v, harmonics)
    rows = []
    for out in ("dz", "thy"):
        dd, ddj = (d, d_jac) if out == "thy" else (None, None)
        terms = candidate_terms(8, out, positive=v.min(axis=0) > 0, harmonics=harmonics, harmonic_degree=3,
                                d_terms=out == "thy")
        X, y = design_matrix(terms, v, dd, harmonics), ds.target(out)
        data = compress(X, y)
        extra = [rounding_rows(data, u)] if u else []

        def qr_fold():
            return compress(None, y[:0], start=data, extra=[*extra, *noise_blocks(terms, v, sigma, dd, ddj,
                                                                                  harmonics=harmonics)])

        def gram_fold():
            return compress(None, y[:0], start=data, extra=extra,
                            gram=noise_gram(terms, v, sigma, dd, ddj, harmonics=harmonics))

        # QR, Gram, QR, Gram, ...: a change in the machine's load lands on both folds, and each round's ratio
        # compares two runs a few seconds apart. One untimed round first: the first fold of an output pays for
        # its first large allocations (up to 1.5x its later times in a trial), which would always fall on QR.
        qr_fold(), gram_fold()
        runs, folds = {"qr": [], "gram": []}, {}
        for k in range(args.rounds):
            for name, fn in (("qr", qr_fold), ("gram", gram_fold)):
                t0 = time.perf_counter()
                folds[name] = fn()
                runs[name].append(time.perf_counter() - t0)
            log(f"{out}: round {k + 1}/{args.rounds}: QR fold {runs['qr'][-1]:.2f} s, "
                f"Gram fold {runs['gram'][-1]:.2f} s")
        ratios = [q / g for q, g in zip(runs["qr"], runs["gram"])]
        plain, folded = folds["qr"], folds["gram"]
        scale = np.linalg.norm(plain, axis=0)
        _, sv, vt = np.linalg.svd(plain[:, :-1] / scale[:-1])
        along = np.sum(((folded[:, :-1] / scale[:-1]) @ vt.T) ** 2, axis=0)
        err = np.abs(along - sv**2) / sv**2
        init = [terms.index(Term(k, e)) for k in range(1, 9) for e in ("-1", "-2")]
        a, b = (stepwise(None, y, init, compressed=R, max_terms=ROWS - 2) for R in (plain, folded))
        rows.append([out, len(terms), f"{statistics.median(runs['qr']):.2f}", f"{statistics.median(runs['gram']):.2f}",
                     f"{statistics.median(ratios):.1f}x ({min(ratios):.1f}-{max(ratios):.1f})",
                     f"{sv[0]:.2g} .. {sv[-1]:.2g}",
                     f"{np.median(err):.1e}", f"{err.max():.1e} (at {sv[np.argmax(err)]:.1e})",
                     "yes" if a.selected == b.selected else "no", f"{abs(a.aic - b.aic) / abs(a.aic):.1e}"])
    head = ["output", "candidates", "QR fold [s]", "Gram fold [s]", "speed-up, median (range)",
            "scaled singular values",
            "Gram's rel. error in |Ax|^2, median", "max (at singular value)", "same choices", "AIC rel. diff."]
    print(f"## Noise rows: QR fold against Gram fold, {ROWS:,} rows, "
          f"{'no rounding rows (--precision exact)' if exact else 'float rounding rows'}\n")
    print("| " + " | ".join(head) + " |")
    print("| " + " | ".join("---" for _ in head) + " |")
    for r in rows:
        print("| " + " | ".join(str(c) for c in r) + " |")
    print(f"\n{args.rounds} rounds after an untimed one, each timing the QR fold and then the Gram fold (the noise "
          f"rows formed and folded into the same data triangle; {'no' if exact else 'with the float'} rounding rows, "
          f"u = {u:.2g}): each fold's median time, and the median and range over the rounds of QR / Gram. Error: "
          "| |F x|^2 - |P x|^2 | / |P x|^2 along each right singular vector x of the column-scaled QR triangle P, "
          "F the Gram fold's.")


if __name__ == "__main__":
    main()
