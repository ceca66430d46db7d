"""What spreads a twin's noise-free held-out figures over its posterior, and how much knowing the stage map would
narrow them.

For units 1..K of bench/units.py (its headline capture: 40 poses, 0.01 mm, magpylib readings, an exact zero):
identify, fit the twin as `fitgen fit` does, then hold the twin's model out (float, noise-free, 2,000 of
bench/units.py's held-out poses) on DRAWS units drawn from the identification's posterior (fitgen's field). Per
output the 5th, 50th and 95th percentile of the RMS error over those units and the ratio 95th / 5th, beside the same
with the posterior conditioned on the stage map (fitgen.fitting.identify.Identification.pinned: the map from the
stage's displacement to the magnet's known exactly), and where the unit's own figure falls among the draws. The
posterior parameter whose draws go most with dz's RMS (the correlation of its squared draw, in prior spreads, with
dz's RMS squared) closes each unit's row. The model file reports the median of such a spread over 8 draws
(docs/calibration.md, "The twin's model file against what the unit delivers"); a spread wider than 1.3^2 = 1.69
from 5th to 95th percentile leaves some units beyond 1.3x of any one figure. A last table gives the odds, per unit,
that the unit (one draw) is within 1.3x of the file on every output's RMS, the file the median of 8 other draws or the
posterior's own median (and the same for the RMS and the max together), and those odds raised to the 20 units the
acceptance line counts.

    python bench/twin_spread.py               # 4 units, 300 draws each: 3 minutes here on 2 cores (175 s)
    python bench/twin_spread.py --units 8 --draws 500
    python bench/twin_spread.py --units 2 --mixture 8    # also a twin fitted on 8 posterior units
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from benchutil import fmt, log, parser, table  # noqa: E402
from identify_bound import SET, _units_module, headline_twin  # noqa: E402
from fitgen.fitting.holdout import posterior_units  # noqa: E402
from fitgen.physics.dataset import Dataset  # noqa: E402
from fitgen.physics.pose import POSE_NAMES  # noqa: E402
from fitgen.physics.transfer import readings  # noqa: E402

HELD = 2000
DRAW_SEED = 5
LIMIT = 1.3  # issue 21: the model file's held-out figures within 1.3x of what the unit delivers
FILE_DRAWS = 8  # posterior units behind the model file's figures (fitgen.fitting.holdout)


def errors(model, R: np.ndarray, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The model's RMS and max |error| per output on readings R (K, n, N) at ``poses``: two (K, outputs)."""
    cols = [POSE_NAMES.index(o) for o in model.output_names]
    K, n, N = R.shape
    err = model.predict(R.reshape(K * n, N), precision="float").reshape(K, n, -1) - poses[None, :, cols]
    return np.sqrt(np.mean(err ** 2, axis=1)), np.max(np.abs(err), axis=1)


def spread(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per column the 5th, 50th, 95th percentile (3, C) and the ratio 95th / 5th (C,)."""
    q = np.quantile(x, [0.05, 0.5, 0.95], axis=0)
    return q, q[2] / q[0]


def draw_params(theta: np.ndarray, cov: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """Parameters (K, P) drawn around ``theta`` with covariance ``cov`` from standard normal ``Z`` (K, P); a
    symmetric square root, since a covariance conditioned on some parameters is singular (no Cholesky)."""
    w, V = np.linalg.eigh((cov + cov.T) / 2)
    return theta[None] + Z @ (V * np.sqrt(np.clip(w, 0.0, None))).T


def odds(free: np.ndarray, seed: int, limit: float = LIMIT, tries: int = 4000) -> tuple[float, float]:
    """The odds that a unit, one draw of ``free`` (K, outputs), has every output's figure within ``limit``x of the
    file's: the file the median of FILE_DRAWS other draws, as the model file reports it, and the posterior's own
    median (as many draws as a file could take)."""
    rng = np.random.default_rng([DRAW_SEED, seed, 1])
    unit = free[rng.integers(len(free), size=tries)]
    files = np.median(free[rng.integers(len(free), size=(tries, FILE_DRAWS))], axis=1)

    def within(f):
        return float(np.mean(np.max(np.maximum(unit / f, f / unit), axis=1) <= limit))

    return within(files), within(np.median(free, axis=0)[None])


def mixture_twin(twin, post: dict, ds: Dataset, k: int):
    """The twin fitted as `fitgen fit` fits it, but on ``k`` units drawn from the posterior (the training poses
    dealt out among them) instead of on the identified unit alone."""
    U, ctx = _units_module()
    parts = [U.simulate(u, ctx.train[c]) for u, c in zip(posterior_units(post, twin, k),
                                                         np.array_split(np.arange(len(ctx.train)), k))]
    mix = Dataset(np.vstack([d.inputs for d in parts]), np.vstack([d.targets for d in parts]), parts[0].target_names,
                  ds.meta)
    return U.fit_default(mix, twin)


def unit_rows(seed: int, draws: int, mixture: int = 0) -> tuple[list[list[str]], tuple[float, ...], list[list[str]]]:
    _, ctx = _units_module()
    unit, ident, twin, post, ds, model = headline_twin(seed)
    poses = ctx.held_poses[:HELD]
    space = ident.space
    Z = np.random.default_rng([DRAW_SEED, seed]).standard_normal((draws, space.size))
    thetas = draw_params(ident.theta, ident.cov, Z)
    R = space.readings(thetas, poses)
    free, free_max = errors(model, R, poses)
    known = errors(model, space.readings(draw_params(ident.theta, ident.pinned("stage."), Z), poses), poses)[0]
    own = errors(model, readings(unit, poses)[None], poses)[0][0]
    (q, ratio), (qk, ratio_k) = spread(free), spread(known)
    dz = model.output_names.index("dz")
    in_sd = space.in_spreads(thetas - ident.theta)
    cor = np.array([np.corrcoef(free[:, dz] ** 2, in_sd[:, i] ** 2)[0, 1] if np.std(in_sd[:, i]) > 0 else 0.0
                    for i in range(space.size)])
    top = int(np.nanargmax(cor))
    rows = []
    for j, o in enumerate(model.output_names):
        rows.append([str(seed), o, f"{fmt(q[0, j])} / {fmt(q[1, j])} / {fmt(q[2, j])}", f"{ratio[j]:.2f}",
                     f"{fmt(qk[0, j])} / {fmt(qk[1, j])} / {fmt(qk[2, j])}", f"{ratio_k[j]:.2f}", fmt(own[j]),
                     f"{100 * np.mean(free[:, j] < own[j]):.0f}",
                     f"{space.names[top]} ({cor[top]:.2f})" if o == "dz" else ""])
    log(f"unit {seed}: spread of dz's RMS {ratio[dz]:.2f}, {ratio_k[dz]:.2f} with the stage map known")
    mixed = []
    if mixture:
        m = mixture_twin(twin, post, ds, mixture)
        (qm, ratio_m), own_m = spread(errors(m, R, poses)[0]), errors(m, readings(unit, poses)[None], poses)[0][0]
        mixed = [[str(seed), o, f"{fmt(q[1, j])} ({ratio[j]:.2f}); {fmt(own[j])}",
                  f"{fmt(qm[1, j])} ({ratio_m[j]:.2f}); {fmt(own_m[j])}"] for j, o in enumerate(model.output_names)]
        log(f"unit {seed}: the twin fitted on {mixture} posterior units")
    return rows, odds(free, seed) + odds(np.hstack([free, free_max]), seed), mixed


def main() -> None:
    ap = parser(__doc__)
    ap.add_argument("--units", type=int, default=4, help="units (bench/units.py's seeds 1..N; default 4)")
    ap.add_argument("--draws", type=int, default=300, help="posterior draws per unit (default 300)")
    ap.add_argument("--mixture", type=int, default=0, metavar="K",
                    help="also fit each twin on K posterior units instead of the identified one (0: not)")
    args = ap.parse_args()
    if args.units < 1 or args.draws < 20 or not 0 <= args.mixture <= 64:
        ap.error("--units must be >= 1, --draws >= 20 and --mixture 0..64")
    per = {seed: unit_rows(seed, args.draws, args.mixture) for seed in range(1, args.units + 1)}
    rows = [row for unit, _, _ in per.values() for row in unit]
    print("## What spreads a twin's noise-free RMS error over its posterior (40 poses, 0.01 mm)\n")
    print(f"Per unit and output: the RMS error (mm, deg; float, noise-free, {HELD} held-out poses) over {args.draws} "
          "units drawn from the identification's posterior, its 5th / 50th / 95th percentile and the ratio 95th / "
          "5th; the same with the stage map known exactly (the posterior conditioned on it); the unit's own figure "
          "and its percentile among the draws. Last column: the parameter whose squared draw goes most with dz's "
          "RMS squared (correlation).\n")
    print(table(["unit", "output", "RMS over the posterior, 5 / 50 / 95 %", "95 / 5", "stage map known, 5 / 50 / 95 %",
                 "95 / 5, stage map known", "the unit's own", "its percentile", "drives dz's spread most"], rows))
    print(f"\n## The odds that the model file's noise-free figures are within {LIMIT:g}x of the unit's\n")
    print(f"Per unit: the unit one draw of its posterior, the file the median of {FILE_DRAWS} other draws (as the "
          "model file reports it) or the posterior's own median (a file of as many draws as it likes); the share of "
          f"4,000 such pairs with every output's noise-free RMS (and, in the last two columns, its max too) within "
          f"{LIMIT:g}x. The last row: the mean over these units, and its power {SET}, the odds that every unit of a "
          f"set of {SET} units like them meets it.\n")
    p = np.array([o for _, o, _ in per.values()])
    out = [[str(seed)] + [f"{100 * x:.0f} %" for x in o] for seed, (_, o, _) in per.items()]
    out.append([f"{SET} units like these"] + [f"{100 * m ** SET:.0f} % (mean {100 * m:.0f} %)" for m in p.mean(0)])
    print(table(["unit", f"RMS; file: median of {FILE_DRAWS} draws", "RMS; file: the posterior's median",
                 f"RMS and max; median of {FILE_DRAWS}", "RMS and max; the posterior's median"], out))
    if args.mixture:
        print(f"\n## A twin fitted on {args.mixture} posterior units instead of the identified one\n")
        print(f"Per unit and output: the noise-free RMS (float) over the same {args.draws} posterior draws, its median "
              "(the ratio 95th / 5th percentile); after ';' the unit's own. A twin fitted across the posterior "
              "would narrow the spread only if part of it were the equations' to absorb.\n")
        print(table(["unit", "output", "the twin (identified unit)", f"fitted on {args.mixture} posterior units"],
                    [row for _, _, mixed in per.values() for row in mixed]))


if __name__ == "__main__":
    main()
