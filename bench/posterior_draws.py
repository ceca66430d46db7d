"""Why a twin's model file widens its held-out figures over Laplace draws of the identification's posterior rather
than over randomise-then-optimise draws: how far each kind of draw, and the unit itself, sits from the maximum a
posteriori on the capture and on held-out poses.

For units 1..N of bench/units.py (draw_unit, paper in gmr), the headline capture with the zero off first contact (40
poses scheduled as `fitgen schedule` does by default, rig error 0.01 mm, the zero off by 0.02 mm rms per axis,
magpylib readings, rows of 16 samples) identified as fitgen identify does (zero error 0.02 mm allowed for). Then:

- Laplace: the POSTERIOR_UNITS = 8 units the model file draws (fitgen.fitting.holdout.posterior_units on the
  posterior record fitgen identify writes: theta_MAP + L g).
- RTO (randomise-then-optimise): 8 units, each the maximum a posteriori solved again from the MAP with the whitened
  residual perturbed by eps ~ N(0, I) and the prior's mean by xi ~ N(0, I) (the rows' whitening kept at the MAP's);
  exact samples for a linear-Gaussian model, a better fit to a curved valley than theta_MAP + L g.

Per unit: the capture's chi-square above its value at the MAP (rows whitened at the MAP) for the unit's own
parameters, the Laplace draws (median, max) and the RTO draws (median, max), beside tr(F C), what a draw of the
linearised posterior adds on average (F the capture's information, C the posterior covariance, in prior spreads);
then the rms deviation of each unit's noise-free readings from the MAP's, in units of the capture's row noise (0.5 mV
over sqrt(16)), on bench/units.py's 2,000 held-out poses (the model file's: the twin's pose box, pose seed 2026) with
all five components and with their tilts set to 0 (three-axis); the truth's, the Laplace draws' median, the RTO
draws' median; and the seconds the 8 RTO draws took. The question: the Laplace draws sit outside the capture's
valley (their chi-square well above tr(F C), where RTO draws and the truth sit), but the twin's figures are computed
on held-out poses, and there the truth need not be nearer the MAP than the Laplace draws; the last line counts the
units whose truth lies beyond the draws' median there.

    python bench/posterior_draws.py             # 4 units: 27-44 s here on 2 busy cores
    python bench/posterior_draws.py --units 8
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parent))

from benchutil import log, parser, table  # noqa: E402
from identify_bound import _units_module  # noqa: E402
from fitgen.fitting.holdout import POSTERIOR_UNITS, posterior_units  # noqa: E402
from fitgen.fitting.identify import identify  # noqa: E402
from fitgen.fitting.unitrecord import unit_files  # noqa: E402
from fitgen.physics.transfer import readings  # noqa: E402

RTO_SEED = 99
RTO_NFEV = 30  # function evaluations per RTO draw (from the MAP it converges in a few)


def rto_thetas(ident, k: int, seed: int) -> np.ndarray:
    """``k`` randomise-then-optimise draws (k, P), physical units: the MAP problem with the whitened residual shifted
    by eps ~ N(0, I) and the prior's mean by xi ~ N(0, I) (free parameters), solved from the MAP, the rows' whitening
    the MAP's."""
    prob, space = ident.problem, ident.space
    P, z0 = space.size, space.in_spreads(ident.theta)
    js = prob.pose_slopes(z0)
    wh, first = prob.whitening(z0, slopes=js), prob.shift_term(js)
    rng = np.random.default_rng([RTO_SEED, seed])
    out = []
    for _ in range(k):
        eps, xi = rng.standard_normal(prob.readings.size), rng.standard_normal(P) * space.free
        z = least_squares(lambda z: np.concatenate([wh.apply(prob.readings - prob.predict(z)[0] + first) + eps,
                                                    z - xi]), z0,
                          jac=lambda z: np.vstack([-wh.apply(prob.jacobian(z)), np.eye(P)]), method="lm",
                          max_nfev=RTO_NFEV).x
        out.append(z * space.prior_sd)
    return np.array(out)


def unit_row(seed: int) -> tuple[list[str], list[bool]]:
    U, ctx = _units_module()
    labels = ctx.schedules[(*U.HEAD, U.ZEROED)]  # scheduled as fitgen schedule does for a zero off by 0.02 mm
    unit, _ = U.draw_unit(ctx.drawing, seed)
    y = U.capture(unit, labels, U.HEAD[1], [seed, len(labels), 3], U.ZERO_SIM)  # bench/units.py's zero-off capture
    ident = identify(ctx.drawing, y, labels, ctx.noise / np.sqrt(U.SAMPLES), rig_error=U.HEAD[1],
                     zero_error=U.ZERO_SIM)
    prob, space = ident.problem, ident.space
    record = json.loads(unit_files(ident, "unit.toml", {"drawing_spec": U.PRESET})[1][1])  # what identify writes
    laplace = posterior_units(record, ctx.drawing, POSTERIOR_UNITS)
    t = time.monotonic()
    rto = [space.sensor(th) for th in rto_thetas(ident, POSTERIOR_UNITS, seed)]
    seconds = time.monotonic() - t
    groups = {"truth": [unit], "laplace": laplace, "rto": rto, "map": [ident.unit()]}
    wh = prob.whitening(space.in_spreads(ident.theta))

    def at(poses):  # noise-free readings (K, n, N) of every group's units at ``poses``
        return {k: np.array([readings(u, poses, adc_bits=0) for u in us]) for k, us in groups.items()}

    cap = at(labels)
    chi2 = {k: np.array([np.sum(wh.apply(prob.readings - r) ** 2) for r in R]) for k, R in cap.items()}
    above = {k: v - chi2["map"][0] for k, v in chi2.items()}
    trace = prob.usable(space.in_spreads(ident.theta)).sum() - ident.dof  # tr(F C): the readings' count less it
    three = ctx.held_poses.copy()
    three[:, 3:] = 0.0
    dev = {}
    for name, poses in (("5-axis", ctx.held_poses), ("3-axis", three)):
        R = at(poses)
        dev[name] = {k: np.sqrt(np.mean(((v - R["map"]) / prob.noise) ** 2, axis=(1, 2))) for k, v in R.items()}
    d5, d3 = dev["5-axis"], dev["3-axis"]
    row = [str(seed), f"{ident.reduced_chi2:.2f}", f"{above['truth'][0]:.0f}",
           f"{np.median(above['laplace']):.0f} / {above['laplace'].max():.0f}",
           f"{np.median(above['rto']):.0f} / {above['rto'].max():.0f}",
           f"{trace:.1f}"]
    for d in (d5, d3):
        row += [f"{d['truth'][0]:.1f}", f"{np.median(d['laplace']):.1f}", f"{np.median(d['rto']):.1f}"]
    row.append(f"{seconds:.1f}")
    log(f"unit {seed}: chi-square above the MAP: truth {above['truth'][0]:.0f}, Laplace median "
        f"{np.median(above['laplace']):.0f}, RTO median {np.median(above['rto']):.0f}; 5-axis rms deviation: truth "
        f"{d5['truth'][0]:.1f}, Laplace {np.median(d5['laplace']):.1f}, RTO {np.median(d5['rto']):.1f}")
    # what the closing line counts: the Laplace and the RTO draws' median chi-square above tr(F C); the truth beyond
    # the Laplace and the RTO draws' median deviation, with five axes and with three
    return row, ([np.median(above[k]) > trace for k in ("laplace", "rto")]
                 + [d["truth"][0] > np.median(d[k]) for k in ("laplace", "rto") for d in (d5, d3)])


def main() -> None:
    ap = parser(__doc__)
    ap.add_argument("--units", type=int, default=4, help="units (bench/units.py's seeds 1..N; default 4)")
    args = ap.parse_args()
    if args.units < 1:
        ap.error("--units must be >= 1")
    U, ctx = _units_module()
    rows, flags = [], []
    for seed in range(1, args.units + 1):
        row, f = unit_row(seed)
        rows.append(row)
        flags.append(f)
    n = len(rows)
    print("## Laplace and randomise-then-optimise draws of an identification's posterior, against the unit itself\n")
    print(f"Per unit (bench/units.py's seeds; 40 poses, rig error {U.HEAD[1]:g} mm, zero off {U.ZERO_SIM:g} mm rms, "
          f"{U.SAMPLES} samples per row): the capture's chi-square above its value at the MAP for the unit's own "
          f"parameters, the {POSTERIOR_UNITS} Laplace units the model file draws (median / max) and {POSTERIOR_UNITS} "
          "RTO units (median / max), beside tr(F C), a linearised posterior draw's mean; the rms deviation of each "
          f"unit's noise-free readings from the MAP's, in the capture's row noise ({1e3 * ctx.noise:g} mV / "
          f"sqrt({U.SAMPLES})), on the model file's {len(ctx.held_poses)} held-out poses with all five components and "
          "with the tilts at 0 (truth; median over the Laplace and over the RTO units); the RTO draws' seconds.\n")
    print(table(["unit", "reduced chi-square", "chi-square above the MAP: truth", "Laplace, median / max",
                 "RTO, median / max", "tr(F C)", "5-axis rms deviation: truth", "Laplace, median", "RTO, median",
                 "3-axis rms deviation: truth", "Laplace, median", "RTO, median", "RTO draws [s]"], rows))
    lap, rto, l5, l3, r5, r3 = np.sum(flags, axis=0)
    print(f"\nOn the capture the draws' median chi-square above the MAP exceeds tr(F C) in {lap} of {n} units for "
          f"Laplace, {rto} of {n} for RTO. On held-out poses the truth lies beyond the Laplace draws' median in {l5} of "
          f"{n} units with five axes and {l3} of {n} with three; beyond the RTO draws' median in {r5} and {r3} of {n}.")


if __name__ == "__main__":
    main()
