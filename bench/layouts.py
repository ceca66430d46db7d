"""The layout study: the paper's single ring beside other arrangements of eight elements.

Run: ``python bench/layouts.py > /tmp/layouts.md`` (markdown on stdout, progress on stderr;
about 5 s on 2 cores). Tables and their reading: docs/layouts.md.

Layouts: the sensor presets ``paper`` (the reference: 8 radial elements, r = 10 mm),
``two-rings`` (4 radial at r = 10 mm on the board's bottom face, 4 radial at r = 6 mm on its
top face), ``two-radii`` (the same two rings, both on the bottom face: the planar control) and
``ring-vertical`` (the paper's 8 positions, 4 radial and 4 with a +z axis) and ``tilted-axes``
(two rings of 4, at r = 8.5 mm radial on the bottom face and at r = 8.1 mm on the top face with their radial
axes raised 25 deg toward +z; bench/layout_search.py found it). All share the
magnet, board, element noise (0.5 uT rms) and the ``raw`` transfer (|B . axis| in mT).

1. Readings: the smallest and largest reading over the training grid and the evaluation
   poses; the share of grid poses with a reading beyond 2 mT, where the AA003-02 saturates
   (the raw transfer does not); and the worst thx bound of scene full under the gmr transfer.
2. Observability (fitgen.physics.observe): the Jacobian d(readings)/d(pose) at rest, its rank
   (singular values above 1e-8 of the largest) and smallest singular value; Cramer-Rao
   bounds at the sensor's noise, at rest and the worst over the 32 corners of the scene's
   box; scene ``full`` (all five components jointly) and scene ``slide`` (dx, dy, dz; tilt
   held at 0).
3. Fitted accuracy, scene full: fit_model on the paper-sim grid (1,875 poses) simulated
   without noise; evaluated on 2,000 random poses uniform in the same box (pose seed 2026,
   as bench/paper_reproduction.py), without noise and with the sensor's noise (noise seed 1).
   Also a fit on the same grid with the sensor's noise (noise seed 2), evaluated with noise,
   and the noise gain of both fits' dz equation at (0, 0, -1, 0, 0): the norm of the
   gradient of the estimate by the readings (central differences), beside the Cramer-Rao
   bound on dz there.
   And the paper's Figure 7 sweep: thx from -5 to 5 deg in 0.1 deg steps, all else 0 (no
   noise): the least-squares slope of the estimate against the true thx (1 is ideal).
4. Fitted accuracy, scene slide: fit on the scene's grid (5 x 5 x 5 levels of dx, dy, dz,
   tilt 0; 125 poses) without noise, outputs dx, dy, dz; evaluated on 2,000 random poses in
   its box (pose seed 2026), without and with the sensor's noise; and fitted on the scene's
   grid with the sensor's noise (noise seed 2), evaluated with noise.
5. How much the fit depends on the inner ring's radius: two-rings and two-radii with the inner
   radius 5, 6 and 7 mm, fitted and evaluated as in 3 (no noise).
6. What separates tilt from slide: the paper ring's outer 4 elements plus a second group of
   4 (turned 45 deg) at other radii, heights and axes; smallest singular value at rest and
   the worst thx bound of scene full (observability only, no fit).
"""

from __future__ import annotations

import sys

import numpy as np

from fitgen.fitting.fit import FitSettings, error_stats, fit_model
from fitgen.physics.observe import jacobian, observe
from fitgen.physics.pose import POSE_NAMES
from fitgen.physics.scenes import PRESETS
from fitgen.base.texts import tomllib
from fitgen.physics.sensor import load_sensor, parse_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, pose_rng, random_poses, simulate
from benchutil import fmt, log, parse_args, table

LAYOUTS = ("paper", "two-rings", "two-radii", "ring-vertical", "tilted-axes")
N_EVAL = 2000
POSE_SEED = 2026
EVAL_NOISE_SEED = 1
FIT_NOISE_SEED = 2
SATURATION = 2.0  # mT, the AA003-02's (transfer.gmr.saturation in every preset)
RANK_TOL = 1e-8  # singular values below this fraction of the largest count as zero
# the study fits as the paper does (data as given, exact arithmetic); docs/deployed-accuracy.md
# has the same layouts fitted for the device
EXACT = FitSettings.exact()



def corner_worst(rep) -> np.ndarray:
    """The worst bound per component over rest and the box's corners (the poses observe judges inside the box
    are left out: this study compares layouts at the corners)."""
    return np.max([x.bounds for x in rep.results[:len(rep.results) - rep.inside]], axis=0)

def rank_at_rest(sensor) -> tuple[int, np.ndarray]:
    s = np.linalg.svd(jacobian(sensor, np.zeros(5))[0], compute_uv=False)
    return int(np.sum(s > RANK_TOL * s[0])), s


def errors(model, ds, outputs) -> dict:
    pred = model.predict(ds.inputs)
    return {o: error_stats(pred[:, j] - ds.target(o)) for j, o in enumerate(outputs)}


def cell(stats: dict) -> str:
    return f"{fmt(stats['max'])} / {fmt(stats['rms'])}"


def noise_gain(model, sensor, pose=(0.0, 0.0, -1.0, 0.0, 0.0), output="dz") -> float:
    """|d estimate / d readings| (central differences) at ``pose``: the estimate's rms per unit of
    independent element noise."""
    v0 = simulate(sensor, np.array([pose])).inputs[0]
    j = [eq.name for eq in model.equations].index(output)
    h = 1e-6
    probe = np.vstack([v0 + h * np.eye(len(v0)), v0 - h * np.eye(len(v0))])
    est = model.predict(probe)[:, j]
    return float(np.linalg.norm((est[: len(v0)] - est[len(v0):]) / (2 * h)))


def study(name: str) -> dict:
    sensor = load_sensor(name)
    full, slide = PRESETS["full"], PRESETS["slide"]
    out = {"sensor": sensor}

    log(f"{name}: observability")
    out["rank"], out["sv"] = rank_at_rest(sensor)
    out["obs_full"] = observe(sensor, full.ranges, full.outputs)
    out["obs_slide"] = observe(sensor, slide.ranges, slide.outputs)

    log(f"{name}: fit, scene full (paper-sim grid)")
    grid = grid_poses(PAPER_GRIDS["paper-sim"])
    rand = random_poses(N_EVAL, full.ranges, pose_rng(POSE_SEED))
    train = simulate(sensor, grid)
    model = fit_model(train, settings=EXACT)
    clean = simulate(sensor, rand)
    noisy = simulate(sensor, rand, noise=sensor.noise, seed=EVAL_NOISE_SEED)
    out["terms"] = {eq.name: len(eq.terms) for eq in model.equations}
    out["clean"] = errors(model, clean, POSE_NAMES)
    out["noisy"] = errors(model, noisy, POSE_NAMES)
    both = np.vstack([train.inputs, clean.inputs])
    out["reading_range"] = (float(both.min()), float(both.max()))
    out["saturated"] = float(np.mean(np.any(train.inputs > SATURATION, axis=1)))
    out["gmr_thx"] = float(observe(sensor.with_transfer("gmr"), full.ranges, full.outputs).worst[3])

    sweep = np.zeros((101, 5))
    sweep[:, 3] = np.linspace(-5, 5, 101)
    est = model.predict(simulate(sensor, sweep).inputs)[:, 3]
    out["sweep_slope"] = float(np.polyfit(sweep[:, 3], est, 1)[0])

    log(f"{name}: fit on the noisy grid")
    model_n = fit_model(simulate(sensor, grid, noise=sensor.noise, seed=FIT_NOISE_SEED), settings=EXACT)
    out["terms_noisy_fit"] = {eq.name: len(eq.terms) for eq in model_n.equations}
    out["noisy_fit"] = errors(model_n, noisy, POSE_NAMES)
    out["gain"] = (noise_gain(model, sensor), noise_gain(model_n, sensor))

    log(f"{name}: fit, scene slide")
    srand = random_poses(N_EVAL, slide.ranges, pose_rng(POSE_SEED))
    smodel = fit_model(simulate(sensor, slide.poses(), targets=slide.outputs), settings=EXACT)
    out["slide_terms"] = {eq.name: len(eq.terms) for eq in smodel.equations}
    out["slide_clean"] = errors(smodel, simulate(sensor, srand, targets=slide.outputs), slide.outputs)
    snoisy = simulate(sensor, srand, noise=sensor.noise, seed=EVAL_NOISE_SEED, targets=slide.outputs)
    out["slide_noisy"] = errors(smodel, snoisy, slide.outputs)
    smodel_n = fit_model(simulate(sensor, slide.poses(), noise=sensor.noise, seed=FIT_NOISE_SEED,
                                  targets=slide.outputs), settings=EXACT)
    out["slide_noisy_fit"] = errors(smodel_n, snoisy, slide.outputs)
    out["slide_terms_noisy_fit"] = {eq.name: len(eq.terms) for eq in smodel_n.equations}
    return out


def variant(second: dict):
    """The paper's outer 4 (0, 90, 180, 270 deg, radial, r = 10, z = 0) plus a second ring of 4."""
    from importlib import resources

    data = tomllib.loads(resources.files("fitgen.physics.presets").joinpath("paper.toml").read_text())
    data["name"] = "variant"
    data["elements"] = {"ring": [{"count": 4, "radius": 10.0, "z": 0.0, "start": 0.0, "axis": "radial"},
                                 {"count": 4, "start": 45.0, **second}]}
    return parse_sensor(data, "variant")


def main() -> int:
    parse_args(__doc__)  # no options: one it does not know is refused, not ignored
    results = {name: study(name) for name in LAYOUTS}
    full, slide = PRESETS["full"], PRESETS["slide"]

    print("# Layout study (bench/layouts.py)\n")
    print("## Layouts and their readings\n")
    rows = []
    for name, r in results.items():
        s = r["sensor"]
        lo, hi = r["reading_range"]
        rows.append([f"`{name}`", s.description, fmt(lo), fmt(hi), f"{100 * r['saturated']:.0f} %",
                     fmt(r["gmr_thx"])])
    print(table(["preset", "elements", "min reading [mT]", "max reading [mT]", "grid poses with a reading > 2 mT",
                 "thx worst bound, gmr [deg]"], rows))
    print("\nReadings (raw transfer, no noise) over the paper-sim grid and the 2,000 evaluation poses; the share "
          "of the paper-sim grid's poses where some element reads beyond the AA003-02's 2 mT saturation; and "
          "the worst Cramer-Rao bound on thx of scene full under the `gmr` transfer (at rest, the corners and "
          "200 random poses inside the box: volts, saturating at 2 mT, "
          "0.5 mV noise), where those readings clip.\n")

    print("## Observability, scene full (dx, dy, dz, thx, thy jointly)\n")
    print(f"Jacobian at rest: rank (singular values above {RANK_TOL:g} of the largest), smallest and largest "
          "singular value [mT per mm or deg]. Cramer-Rao bounds (1 sigma, noise 0.5 uT rms) at rest, and the "
          "worst over the 32 corners of the box (dx, dy +-2 mm, dz 0 / -2 mm, thx, thy +-5 deg).\n")
    head = ["layout", "rank at rest", "s_min at rest", "s_max"]
    head += [f"{c} at rest" for c in POSE_NAMES] + [f"{c} worst corner" for c in POSE_NAMES]
    rows = []
    for name, r in results.items():
        rep = r["obs_full"]
        rest = rep.results[0].bounds
        corners = np.max([x.bounds for x in rep.results[1:len(rep.results) - rep.inside]], axis=0)
        rows.append([f"`{name}`", str(r["rank"]), fmt(r["sv"][-1]), fmt(r["sv"][0])]
                    + [fmt(b) for b in rest] + [fmt(b) for b in corners])
    print(table(head, rows))
    print("\nBounds in mm (dx, dy, dz) and deg (thx, thy).\n")

    print("## Observability, scene slide (dx, dy, dz; tilt held at 0)\n")
    rows = []
    for name, r in results.items():
        rep = r["obs_slide"]
        J = jacobian(r["sensor"], np.zeros(5))[0][:, :3]
        sv = np.linalg.svd(J, compute_uv=False)
        rows.append([f"`{name}`", str(int(np.sum(sv > RANK_TOL * sv[0]))), fmt(sv[-1])]
                    + [fmt(b) for b in rep.results[0].bounds] + [fmt(b) for b in corner_worst(rep)])
    print(table(["layout", "rank at rest", "s_min at rest"] + [f"{c} at rest" for c in slide.outputs]
                + [f"{c} worst" for c in slide.outputs], rows))
    print()

    print("## Fitted accuracy, scene full\n")
    print("Fit: paper-sim grid (1,875 poses), no noise. Evaluation: 2,000 random poses in the same box. "
          "Cells: max / RMS error (mm for dx, dy, dz; deg for thx, thy).\n")
    print("### Terms per output\n")
    rows = [[f"`{n}`"] + [str(r["terms"][c]) for c in POSE_NAMES] + [str(sum(r["terms"].values()))]
            for n, r in results.items()]
    print(table(["layout"] + list(POSE_NAMES) + ["total"], rows))
    for key, title in (("clean", "Evaluated without noise"),
                       ("noisy", "Evaluated with the sensor's noise (0.5 uT rms per element)")):
        print(f"\n### {title}\n")
        rows = [[f"`{n}`"] + [cell(r[key][c]) for c in POSE_NAMES] for n, r in results.items()]
        print(table(["layout"] + list(POSE_NAMES), rows))
    print("\n### Fitted on the grid with the sensor's noise, evaluated with noise\n")
    rows = [[f"`{n}`"] + [cell(r["noisy_fit"][c]) for c in POSE_NAMES]
            + [" / ".join(str(r["terms_noisy_fit"][c]) for c in POSE_NAMES)] for n, r in results.items()]
    print(table(["layout"] + list(POSE_NAMES) + ["terms"], rows))
    print("\n### Noise gain of the dz equation at (0, 0, -1, 0, 0)\n")
    print("|d dz_estimate / d readings| [mm per mT]: the estimate's rms per mT of independent element noise; "
          "times 0.0005 mT, the dz scatter the sensor's noise causes there. Beside it, the Cramer-Rao bound "
          "at that pose (all five components estimated).\n")
    rows = []
    for n, r in results.items():
        crb = observe(r["sensor"], {c: (v, v) for c, v in zip(POSE_NAMES, (0.0, 0.0, -1.0, 0.0, 0.0))},
                      POSE_NAMES).results[0].bounds[2]
        g0, g1 = r["gain"]
        noise = r["sensor"].noise
        rows.append([f"`{n}`", fmt(g0), fmt(g0 * noise), fmt(g1), fmt(g1 * noise), fmt(crb)])
    print(table(["layout", "gain, fitted without noise", "dz rms from noise [mm]", "gain, fitted with noise",
                 "dz rms from noise [mm]", "Cramer-Rao bound on dz [mm]"], rows))
    print("\n### The paper's Figure 7 sweep (thx -5..5 deg at rest, no noise)\n")
    rows = [[f"`{n}`", f"{r['sweep_slope']:.3f}"] for n, r in results.items()]
    print(table(["layout", "slope of estimated against true thx (1 is ideal)"], rows))
    print()

    print("## Fitted accuracy, scene slide (dx, dy, dz; tilt 0)\n")
    print("Fit: the scene's grid (125 poses), no noise. Evaluation: 2,000 random poses in its box. "
          "Cells: max / RMS error in mm.\n")
    rows = [[f"`{n}`", " / ".join(str(r["slide_terms"][c]) for c in slide.outputs)]
            + [cell(r["slide_clean"][c]) for c in slide.outputs] + [cell(r["slide_noisy"][c]) for c in slide.outputs]
            for n, r in results.items()]
    print(table(["layout", "terms"] + [f"{c}" for c in slide.outputs] + [f"{c}, noise" for c in slide.outputs], rows))
    print("\nFitted on the scene's grid with the sensor's noise, evaluated with noise:\n")
    rows = [[f"`{n}`", " / ".join(str(r["slide_terms_noisy_fit"][c]) for c in slide.outputs)]
            + [cell(r["slide_noisy_fit"][c]) for c in slide.outputs] for n, r in results.items()]
    print(table(["layout", "terms"] + [f"{c}, noise" for c in slide.outputs], rows))
    print()

    log("how much the fit depends on the inner radius")
    print("## How much the fit depends on the inner ring's radius\n")
    print("`two-rings` (inner ring on the top face, z = 1.5 mm) and `two-radii` (z = 0) with the inner "
          "radius changed; fitted as in scene full (paper-sim grid, no noise), evaluated on the same 2,000 "
          "random poses without noise. Cells: max / RMS error.\n")
    grid = grid_poses(PAPER_GRIDS["paper-sim"])
    rand = random_poses(N_EVAL, full.ranges, pose_rng(POSE_SEED))
    rows = []
    for z2 in (1.5, 0.0):
        for r2 in (5.0, 6.0, 7.0):
            s = variant({"radius": r2, "z": z2, "axis": "radial"})
            model = fit_model(simulate(s, grid), settings=EXACT)
            err = errors(model, simulate(s, rand), POSE_NAMES)
            _, sv = rank_at_rest(s)
            rows.append([f"{r2:g}", f"{z2:g}", fmt(sv[-1]), str(sum(len(eq.terms) for eq in model.equations))]
                        + [cell(err[c]) for c in ("dx", "dz", "thx")])
    print(table(["inner radius [mm]", "z [mm]", "s_min at rest", "terms (all 5)", "dx", "dz", "thx"], rows))
    print()

    log("what separates tilt from slide")
    print("## What separates tilt from slide at rest\n")
    print("The paper's outer 4 elements (r = 10 mm, z = 0, radial, 0/90/180/270 deg) plus 4 more at "
          "45/135/225/315 deg. Smallest singular value of the Jacobian at rest [mT per mm or deg] and "
          "the worst Cramer-Rao bound on thx over rest and the corners of scene full [deg].\n")
    rows = []
    variants = [("radial", r2, 0.0) for r2 in (4.0, 6.0, 8.0, 10.0, 12.0)]
    variants += [("radial", r2, 1.5) for r2 in (6.0, 10.0)]
    variants += [("z", r2, 0.0) for r2 in (6.0, 10.0)]
    for axis, r2, z2 in variants:
        s = variant({"radius": r2, "z": z2, "axis": axis})
        rank, sv = rank_at_rest(s)
        rep = observe(s, full.ranges, full.outputs)
        rows.append([axis, f"{r2:g}", f"{z2:g}", str(rank), fmt(sv[-1]), fmt(corner_worst(rep)[3])])
    print(table(["second 4: axis", "radius [mm]", "z [mm]", "rank at rest", "s_min at rest", "thx worst bound"], rows))
    log("done")
    return 0


if __name__ == "__main__":
    sys.exit(main())
