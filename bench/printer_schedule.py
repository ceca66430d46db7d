"""A printer's stage and the schedule made for it: captures through a simulated G-code stage whose repeatability
and hand-set zero lift rows at first contact off the skin, from three schedules: one that keeps first contact
(`fitgen schedule --zero-error 0`, made for a 0.01 mm stage with an exact zero), the default (0.01 mm, a zero off by
0.02 mm rms) and one made for the stage (`fitgen schedule --rig-error R`), whose rows in contact stand
fitgen.physics.pose.contact_top below first contact.

Units of paper in gmr (fitgen.physics.units.draw_unit, seeds 11..), each captured at 40 poses through
host.stagesim.simulated_stage_capture (GRBL on a socket, a rig with R mm rms repeatability per axis and 0.1 mm
backlash, zeroed off first contact by one draw per unit, normal with --zero-off mm rms per axis, as a zero set by
hand is; 16 samples per row), from each schedule, and identified as `fitgen identify --rig-error R` does (its
default --zero-error 0.02; fitgen.fitting.identify.identify, then fitgen.fitting.verdict.check_explained's
refusal). Per schedule: the rows in contact that read as the rest rows
(the stage's error lifted the indenter past the skin's adhesion, and the magnet rested:
fitgen.fitting.capturecheck.reads_at_rest), the captures with such a row, the captures refused, what the refusals named,
the reduced chi-square of those accepted.

    python bench/printer_schedule.py              # about 5 minutes here on 2 cores
    python bench/printer_schedule.py --units 5    # a quick look
"""

from __future__ import annotations

import re
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from benchutil import log, parser, table  # noqa: E402
from fitgen.base.errors import InputError  # noqa: E402
from fitgen.fitting.capturecheck import REST_LIKE, reads_at_rest  # noqa: E402
from fitgen.fitting.identify import RIG_ERROR, ZERO_ERROR, identify  # noqa: E402
from fitgen.fitting.schedule import schedule, write_schedule  # noqa: E402
from fitgen.fitting.unitrecord import row_noise  # noqa: E402
from fitgen.fitting.verdict import check_explained  # noqa: E402
from fitgen.physics.dataset import load_dataset  # noqa: E402
from fitgen.physics.pose import off_skin  # noqa: E402
from fitgen.physics.sensor import load_sensor  # noqa: E402
from fitgen.physics.units import draw_unit  # noqa: E402
from host.capture import load_schedule  # noqa: E402
from host.stagesim import simulated_stage_capture  # noqa: E402

N_POSES, SAMPLES, BACKLASH, FIRST_SEED = 40, 16, 0.1, 11


def one(drawing, unit, plan: Path, rig: float, zero: np.ndarray, seed: int, folder: Path) -> dict:
    """One capture of ``unit`` from the schedule at ``plan`` through the simulated stage zeroed ``zero`` (mm) off
    first contact, and its identification."""
    cap = folder / f"capture-{seed}-{plan.stem}.csv"
    simulated_stage_capture(unit, load_schedule(plan), cap, flavor="grbl", samples=SAMPLES, backlash=BACKLASH,
                            repeatability=rig, seed=seed, zero_off=zero)
    ds = load_dataset(cap)
    noise, source = row_noise(ds.meta, drawing, None)
    out = {"lost": int(reads_at_rest(ds.inputs, ds.poses(), noise).sum())}
    ident = identify(drawing, ds.inputs, ds.poses(), noise, rig_error=rig)
    try:
        check_explained(ident, str(cap), drawing.name, source)
        out["chi2"] = ident.reduced_chi2
    except InputError as exc:
        named = re.search(r"row \d+ \(line \d+: [^)]*\)", str(exc))
        out["refused"] = named.group(0) if named else "no single row"
    return out


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--units", type=int, default=20, help="units (seeds 11..; default 20)")
    ap.add_argument("--rig-error", type=float, default=0.03, help="the stage's repeatability, mm rms (default 0.03)")
    ap.add_argument("--zero-off", type=float, default=ZERO_ERROR,
                    help=f"the hand-set zero's error, mm rms per axis (default {ZERO_ERROR:g}, identify's default)")
    args = ap.parse_args(argv)
    if args.units < 1 or not 0 < args.rig_error <= 0.1 or not 0 <= args.zero_off <= 0.1:
        ap.error("--units must be >= 1, --rig-error within 0..0.1 mm and --zero-off within 0..0.1 mm")
    drawing = load_sensor("paper").with_transfer("gmr")
    plans = {}
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for made_for in ((RIG_ERROR, 0.0), (RIG_ERROR, ZERO_ERROR), (args.rig_error, ZERO_ERROR)):
            poses, info = schedule(drawing, N_POSES, noise=drawing.noise / np.sqrt(SAMPLES), rig_error=made_for[0],
                                   zero_error=made_for[1])
            plans[made_for] = (folder / f"for-{made_for[0]:g}-{made_for[1]:g}.csv", poses)
            write_schedule(plans[made_for][0], poses, ("dx", "dy", "dz"), {**info, "samples_per_row": SAMPLES})
            results[made_for] = []
        for i, seed in enumerate(range(FIRST_SEED, FIRST_SEED + args.units)):
            unit, _ = draw_unit(drawing, seed)
            zero = np.random.default_rng([seed, 5]).normal(0.0, args.zero_off, 3)  # one zero per unit, every schedule
            for made_for, (plan, _) in plans.items():
                r = one(drawing, unit, plan, args.rig_error, zero, seed, folder)
                results[made_for].append(r)
                log(f"[{i + 1}/{args.units}] unit {seed}, schedule for {made_for[0]:g} mm, zero {made_for[1]:g} mm: "
                    f"{r['lost']} row(s) off the skin, "
                    + (f"refused ({r['refused']})" if "refused" in r else f"chi2/dof {r['chi2']:.2f}"))
    rows = []
    for made_for, (_, poses) in plans.items():
        res = results[made_for]
        contact = poses[~off_skin(poses)]
        chi = [r["chi2"] for r in res if "chi2" in r]
        refused = [r["refused"] for r in res if "refused" in r]
        default = " (the default)" * (made_for == (RIG_ERROR, ZERO_ERROR))
        rows.append([f"{made_for[0]:g} mm, zero {made_for[1]:g} mm{default}", f"{contact[:, 2].max():g}",
                     str(int(np.sum(contact[:, 2] == contact[:, 2].max()))),
                     f"{sum(r['lost'] for r in res)} of {len(res) * len(contact)}",
                     f"{sum(r['lost'] > 0 for r in res)} of {len(res)}", f"{len(refused)} of {len(res)}",
                     f"{sum(x != 'no single row' for x in refused)}",
                     f"{np.median(chi):.2f} ({min(chi):.2f}-{max(chi):.2f})" if chi else "-"])
    print("# A printer's stage and the schedule made for it (bench/printer_schedule.py)\n")
    print(f"paper in gmr, units seeds {FIRST_SEED}..{FIRST_SEED + args.units - 1}, {N_POSES} D-optimal poses, captured "
          f"through host.stagesim's GRBL with {args.rig_error:g} mm rms repeatability and {BACKLASH:g} mm backlash, "
          f"zeroed off first contact by {args.zero_off:g} mm rms per axis (one draw per unit, the same for each "
          f"schedule; {SAMPLES} samples per row), identified with --rig-error {args.rig_error:g} (and the default "
          f"--zero-error {ZERO_ERROR:g}). `off the skin`: rows in "
          f"contact reading as the rest rows (within {REST_LIKE:g} noise sd on every element). `refused`: fitgen "
          "identify's checks; `naming a row`: the refusal names the row to delete. chi2/dof: median (least-greatest) "
          "of the captures accepted.\n")
    print(table(["schedule made for (rig, zero)", "highest dz in contact [mm]", "rows there", "rows off the skin",
                 "captures with one", "captures refused", "naming a row", "chi2/dof accepted"], rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
