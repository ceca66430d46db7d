"""An elastomer that stiffens as it is pressed: what a capture over the sensor's travel makes of it.

identify takes the magnet to follow the stage linearly (the stage-to-magnet map). A real elastomer stiffens as it
is pressed (the layer under the magnet compresses), so the magnet follows less the deeper the press. Model: on the
skin the stage's dz reaches the magnet as dz (1 - c |dz|) before the unit's map, c in 1/mm (c = 0.01: 3 % less at
3 mm deep, 2 % at the working box's 2 mm). For bench/units.py's units 1..N, their headline capture (40 poses,
0.01 mm rig error, magpylib readings, an exact zero) scheduled over the sensor's travel and within the working box
alone, each c: identify's reduced chi-square (median, greatest, and how many captures it refuses), its errors in
the magnet's height and in the worst element's sensitivity (medians over the units: issue 21's line reads 0.03 mm
and 1 %); for units 1..K the twin fitted as `fitgen fit` fits it, held out on the stiffening unit itself (2,000 of
bench/units.py's held-out poses, magpylib, float): dz's noise-free RMS and noisy max (5 draws of the sensor's
noise), the median over the K units.

    python bench/stiffening.py                  # 10 units, twins on 3: about 10 minutes here on 2 cores
    python bench/stiffening.py --units 4 --twins 0
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from benchutil import fmt, log, parser, table  # noqa: E402
from identify_bound import _units_module, twin_of  # noqa: E402
from fitgen.fitting.identify import CHI2_LIMIT, derived_quantities, identify  # noqa: E402
from fitgen.physics.pose import POSE_NAMES, off_skin  # noqa: E402
from fitgen.physics.simulate import rig_poses  # noqa: E402

STIFFENING = (0.0, 0.005, 0.01, 0.02, 0.04)  # c, 1/mm
HELD = 2000
DZ = POSE_NAMES.index("dz")


def stiffen(poses: np.ndarray, c: float) -> np.ndarray:
    """``poses`` (n, 5) with every press (dz < 0) reaching the magnet as dz (1 - c |dz|)."""
    out = np.array(poses, dtype=float)
    dz = out[:, DZ]
    out[:, DZ] = np.where(dz < 0, dz * (1 - c * np.abs(dz)), dz)
    return out


def capture(unit, labels: np.ndarray, c: float, key) -> np.ndarray:
    """bench/units.py's capture (the rig's error, magpylib, noise over sqrt(16)) of a unit whose elastomer stiffens."""
    U, ctx = _units_module()
    rng = np.random.default_rng(key)
    true = rig_poses(labels, U.HEAD[1], rng)
    touching = ~off_skin(labels)
    true[touching] = stiffen(true[touching], c)
    noise = rng.normal(0.0, ctx.noise / np.sqrt(U.SAMPLES), (len(true), unit.n_elements))
    y = U.magpylib_readings(unit, true) + noise
    return np.clip(y, unit.gmr.adc_min, unit.gmr.adc_max)


def held_dz(model, unit, c: float, seed: int) -> tuple[float, float]:
    """The twin's dz on the stiffening unit: noise-free RMS and noisy max (float)."""
    U, ctx = _units_module()
    poses = ctx.held_poses[:HELD]
    truth = U.magpylib_readings(unit, stiffen(poses, c))
    noisy = truth[None] + np.random.default_rng([seed, 7]).normal(0.0, ctx.noise, (ctx.draws,) + truth.shape)
    _, rms = U.figures(model, truth, poses)
    mx, _ = U.figures(model, noisy.reshape(-1, truth.shape[1]), np.tile(poses, (ctx.draws, 1)))
    return float(rms[DZ]), float(mx[DZ])


def rows(units: int, twins: int) -> list[list[str]]:
    U, ctx = _units_module()
    rig, noise = U.HEAD[1], ctx.noise / np.sqrt(U.SAMPLES)
    out = []
    for box, labels in (("travel", ctx.schedules[U.HEAD]), ("working", ctx.schedules[(*U.HEAD, U.WORKING)])):
        for c in STIFFENING:
            chi, height, worst, dz = [], [], [], []
            for seed in range(1, units + 1):
                unit, theta = U.draw_unit(ctx.drawing, seed)
                ident = identify(ctx.drawing, capture(unit, labels, c, [seed, len(labels), 3]), labels, noise,
                                 rig_error=rig, zero_error=0.0)
                truth = {k: fn(theta) for k, fn in derived_quantities(ident.space).items()}
                e, _, _ = U.derived_errors({"derived": ident.derived(), "derived_truth": truth})
                chi.append(ident.reduced_chi2)
                height.append(abs(e[2]))
                worst.append(np.abs(e[3:]).max())
                if seed <= twins:
                    dz.append(held_dz(twin_of(ident)[3], unit, c, seed))
            log(f"{box} box, c = {c:g}/mm: reduced chi-square {np.median(chi):.2f}, height {np.median(height):.3f} mm")
            dz = np.array(dz).reshape(-1, 2)
            out.append([box, f"{c:g}", f"{100 * c * 3:.1f} % / {100 * c * 2:.1f} %",
                        f"{np.median(chi):.2f} ({np.max(chi):.2f})", f"{int(np.sum(np.array(chi) > CHI2_LIMIT))}",
                        fmt(np.median(height)), f"{100 * np.median(worst):.2g} %"]
                       + ([fmt(np.median(dz[:, 0])), fmt(np.median(dz[:, 1]))] if len(dz) else ["-", "-"]))
    return out


def main() -> None:
    ap = parser(__doc__)
    ap.add_argument("--units", type=int, default=10, help="units (bench/units.py's seeds 1..N; default 10)")
    ap.add_argument("--twins", type=int, default=3, help="of them, the first K get a twin held out (default 3)")
    args = ap.parse_args()
    if args.units < 1 or not 0 <= args.twins <= args.units:
        ap.error("--units must be >= 1 and --twins 0..units")
    _, ctx = _units_module()
    print("## An elastomer that stiffens: identify and the twin on units whose magnet follows dz less the deeper\n")
    print(f"{args.units} units (bench/units.py's seeds 1..{args.units}), each captured at 40 poses with a 0.01 mm rig "
          "error (magpylib, an exact zero), the stage's dz reaching the magnet as dz (1 - c |dz|). Reduced chi-square "
          f"median (greatest); refused: above {CHI2_LIMIT:g}. The magnet's height and the worst element's "
          f"sensitivity: median |error| over the units. The twin's dz (units 1..{args.twins}, the median): noise-free "
          f"RMS and noisy max ({ctx.draws} draws), mm, on the stiffening unit itself, {HELD} held-out poses.\n")
    print(table(["schedule", "c [1/mm]", "dz lost at 3 / 2 mm", "reduced chi-square", "refused", "height [mm]",
                 "worst element", "twin's dz RMS, noise-free", "twin's dz noisy max"], rows(args.units, args.twins)))


if __name__ == "__main__":
    main()
