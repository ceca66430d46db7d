"""A field that moves with the stage: what a printer's motors (or a steel bed) do to identify and to the twin, taken
for a static ambient field and allowed for (`[tolerances] stage_field`).

The stage carries its own magnetic field: the extruder's stepper rides on the carriage that holds the indenter,
and a bed may be steel. Where the sensor is, that field changes as the stage moves, and the GMR elements' noise is
0.3 uT rms per sample (0.5 mV through the amplifier), 0.08 uT in a row of 16: a field changing by 1 uT per mm of
travel moves a row by tens of times its noise over the capture. identify's static ambient field cannot explain
it. A drawing whose tolerances give `stage_field` (mT/mm, each entry of the 3x3 matrix from the stage's move to
the field) lets identify fit it as the capture's (the twin, the deployed sensor, carries none).

bench/units.py's units 1..U and headline capture (40 D-optimal poses scheduled for the drawing identify takes,
0.01 mm rig, 16 samples per row, magpylib's readings, an exact zero), with a field G @ (dx, dy, dz) of the stage
added to the ambient field, G drawn per unit (normal entries scaled to the rms given). Per field and identify's
drawing (the preset: a static ambient field; or the preset with stage_field = ALLOW): refusals (fitgen identify's
checks), the reduced chi-square, issue 21's identified quantities (the magnet's height, the worst element) and
errors over standard errors, and the twin's noisy max held out on the unit's truth, as bench/units.py measures it.

    python bench/stage_field.py              # about 15 minutes on 2 cores (19 shared with the test suite)
"""

from __future__ import annotations

import sys
import tempfile
from dataclasses import replace
from multiprocessing import get_context
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from benchutil import fmt, log, parser, table  # noqa: E402
from fitgen.base.errors import InputError  # noqa: E402
from fitgen.fitting.identify import derived_at, identify  # noqa: E402
from fitgen.fitting.schedule import schedule  # noqa: E402
from fitgen.fitting.unitrecord import save  # noqa: E402
from fitgen.fitting.verdict import check_explained  # noqa: E402
from fitgen.physics.pose import POSE_NAMES  # noqa: E402
from fitgen.physics.simulate import rig_poses, simulate  # noqa: E402

import units as U  # noqa: E402

FIELDS = (0.0, 0.0003, 0.001, 0.003)  # mT/mm, rms of G's entries
ALLOW = 0.003  # mT/mm: the tolerance a user who allows for it gives
N, RIG = U.HEAD


def task(spec):
    g, allow, seed = spec
    ctx = U.CTX
    drawing = ctx.allowing if allow else ctx.drawing
    labels = ctx.labels[allow]
    unit, theta = U.draw_unit(ctx.drawing, seed)
    G = np.random.default_rng([seed, 0x6669]).normal(size=(3, 3))
    G *= g / np.sqrt(np.mean(G ** 2))
    rng = np.random.default_rng([seed, N, 3])  # bench/units.py's draws: at g = 0 its headline capture
    true = rig_poses(labels, RIG, rng, None)
    y = U.magpylib_readings(unit, true, stage_field=G) + rng.normal(0.0, ctx.noise / np.sqrt(U.SAMPLES),
                                                                     (len(labels), unit.n_elements))
    y = np.clip(y, unit.gmr.adc_min, unit.gmr.adc_max)
    out = {"spec": spec}
    try:
        ident = identify(drawing, y, labels, ctx.noise / np.sqrt(U.SAMPLES), rig_error=RIG, zero_error=0.0)
        check_explained(ident, f"unit {seed}'s capture", U.PRESET, "the bench's")
    except InputError as exc:
        return {**out, "error": str(exc).splitlines()[0]}
    th = np.concatenate([theta, G.ravel()]) if allow else theta
    truth = derived_at(ident.space, th)
    e, s, _ = U.derived_errors({"derived": ident.derived(), "derived_truth": truth})
    with tempfile.TemporaryDirectory(prefix="fitgen-field-") as tmp:
        path, _ = save(ident, Path(tmp) / "unit.toml", {"capture": f"simulated capture of unit {seed}",
                                                         "drawing_spec": U.PRESET})
        twin = U.load_sensor(path)
        model = U.fit_default(simulate(twin, ctx.train, provenance={"sensor_file": str(path)}), twin)
    return {**out, "chi2": ident.reduced_chi2, "err": np.abs(e), "se": s, **U.measure(model, unit, seed)}


def main() -> None:
    ap = parser(__doc__)
    ap.add_argument("--units", type=int, default=8, help="bench/units.py's units 1..N (default 8)")
    args = ap.parse_args()
    ctx = U.Ctx(U.N_HELD, U.DRAWS, U.N_RANDOM, (U.HEAD,))
    ctx.allowing = replace(ctx.drawing, tolerances=replace(ctx.drawing.tolerances, stage_field=ALLOW))
    ctx.labels = {a: schedule(d, N, noise=ctx.noise / np.sqrt(U.SAMPLES), rig_error=RIG, zero_error=0.0)[0]
                  for a, d in ((False, ctx.drawing), (True, ctx.allowing))}
    U.CTX = ctx
    seeds = list(range(1, args.units + 1))
    specs = [(g, a, s) for g in FIELDS for a in (False, True) for s in seeds]
    log(f"{len(specs)} captures identified and twins fitted on 2 processes")
    results = []
    with get_context("fork").Pool(2) as pool:
        for i, r in enumerate(pool.imap(task, specs), 1):
            results.append(r)
            if i % len(seeds) == 0:
                log(f"{i} of {len(specs)}")
    rows = []
    for g in FIELDS:
        for a in (False, True):
            rs = [r for r in results if r["spec"][:2] == (g, a)]
            ok = [r for r in rs if "error" not in r]
            cells = [f"{1e3 * g:g}", f"stage_field = {ALLOW:g}" if a else "static ambient only",
                     f"{len(rs) - len(ok)} of {len(rs)}"]
            if not ok:
                rows.append(cells + ["-"] * 9)
                continue
            chi2 = np.array([r["chi2"] for r in ok])
            err, se = np.array([r["err"] for r in ok]), np.array([r["se"] for r in ok])
            nm = np.array([r["noisy_max"] for r in ok])
            rows.append(cells + [f"{np.median(chi2):.2f} ({chi2.max():.2f})", fmt(np.median(err[:, 2])),
                                 f"{100 * np.median(err[:, 3:].max(axis=1)):.2g} %",
                                 f"{np.sqrt(np.mean((err / se) ** 2)):.2f}"]
                        + [fmt(np.median(nm[:, j])) for j in range(5)])
    print(f"paper in {U.TRANSFER}, bench/units.py's units {seeds[0]}-{seeds[-1]}, {N} D-optimal poses (scheduled for "
          f"the drawing identify takes), rig {RIG} mm, {U.SAMPLES} samples per row; the field the stage carries: "
          "G @ (dx, dy, dz) of the stage, G's entries normal with the rms given (uT/mm), per unit. `refused`: fitgen "
          "identify's checks (reduced chi-square over 3, or a unit beyond its tolerances). Identified: medians over "
          "the units identify accepts. The twin: noisy max |error| held out on the unit's truth (mm, deg; median "
          "over units), as bench/units.py measures it; the first row is bench/units.py's headline on these units.\n")
    print(table(["field [uT/mm]", "identify's drawing", "refused", "reduced chi-square, median (greatest)",
                 "offset z [mm]", "sensitivity, worst element", "error / standard error, rms"]
                + [f"twin {o}" for o in POSE_NAMES], rows))


if __name__ == "__main__":
    main()
