"""A capture whose zero was set above first contact: identify before and after it took the rows the stage lifted off
the skin as rows at rest. Units of the paper's drawing (UnitSpace draws, seeds 0..), the default 40-pose schedule
(16 of its rows press 0.039 mm), the stage off by 0.01 mm rms, rows of 16 samples, the capture's zero set 0 to 0.2
mm above first contact. A row the rig's error and the zero carry past the skin's adhesion (0.05 mm) reads the magnet
at rest under a label that moves it, which identify's model of the zero (one linear shift of every row in contact)
cannot follow.

Per height: captures accepted before (identify's first fit explains the rows) and now (fitgen.fitting.capturezero.
lifted_rows names the rows in contact that read as the rows off the skin, and identify fits again with them taken
as lifted: fitgen identify's path); whether the rows taken are the rows the stage lifted; where identify found the
zero in dz against where it was set, in standard errors; and the worst of the derived quantities (the magnet's
offset from the elements' centre, each element's sensitivity) against the truth, in standard errors.

    python bench/zero_above.py            # about 10 min here
    python bench/zero_above.py --units 2  # a quick look
    python bench/zero_above.py --sensor tilted-axes --transfer raw --samples 128
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from benchutil import log, parser, table  # noqa: E402
from fitgen.base.errors import InputError  # noqa: E402
from fitgen.fitting.capturezero import lifted_rows  # noqa: E402
from fitgen.fitting.identify import derived_at, identify  # noqa: E402
from fitgen.fitting.schedule import schedule  # noqa: E402
from fitgen.physics.pose import OFF_SKIN_MM, off_skin  # noqa: E402
from fitgen.physics.sensor import load_sensor  # noqa: E402
from fitgen.physics.units import UnitSpace  # noqa: E402

HEIGHTS = (0.0, 0.04, 0.06, 0.08, 0.1, 0.12, 0.15, 0.2, 0.3, 0.5)  # mm above first contact
RIG = 0.01  # mm rms per axis
SAMPLES = 16


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--units", type=int, default=6, help="units per height (default 6)")
    ap.add_argument("--sensor", default="paper", help="the drawing (default paper)")
    ap.add_argument("--transfer", choices=("gmr", "raw"), default="gmr", help="its transfer (default gmr)")
    ap.add_argument("--samples", type=int, default=SAMPLES, help=f"samples per row (default {SAMPLES})")
    ap.add_argument("--heights", default=",".join(f"{h:g}" for h in HEIGHTS),
                    help="zeros above first contact, mm, comma-separated (default %(default)s)")
    args = ap.parse_args(argv)
    if args.units < 1:
        ap.error("--units must be >= 1")
    try:
        heights = [float(h) for h in args.heights.split(",")]
    except ValueError:
        ap.error(f"--heights must be numbers (mm), comma-separated, got {args.heights!r}")
    if args.samples < 1:
        ap.error("--samples must be >= 1")
    try:
        drawing = load_sensor(args.sensor).with_transfer(args.transfer)
    except InputError as exc:
        ap.error(str(exc))
    noise = drawing.noise / np.sqrt(args.samples)
    poses = schedule(drawing, 40, noise=noise)[0]
    contact = ~off_skin(poses)
    space = UnitSpace.of(drawing)
    rows = []
    for height in heights:
        before = after = same = 0
        lifted, zero_z, worst = [], [], []
        for seed in range(args.units):
            rng = np.random.default_rng(seed)
            theta = space.draw(rng)
            true = poses.copy()
            true[contact, :3] += rng.normal(0.0, RIG, (int(contact.sum()), 3)) + [0.0, 0.0, height]
            y = space.readings(theta[None], true)[0] + rng.normal(0.0, noise, (len(poses), drawing.n_elements))
            truly = tuple(int(i) for i in np.flatnonzero(contact & (true[:, 2] > OFF_SKIN_MM)))
            ident = identify(drawing, y, poses, noise, rig_error=RIG)
            before += ident.explained
            taken = lifted_rows(ident)
            if taken:
                again = identify(drawing, y, poses, noise, rig_error=RIG, lifted=taken)
                ident = again if again.explained else ident
            after += ident.explained
            same += taken == truly
            lifted.append(len(truly))
            log(f"zero {height:g} mm above: unit {seed}, {len(truly)} rows lifted, {len(taken)} taken as lifted, "
                f"chi-square {ident.reduced_chi2:.3g}")
            if ident.explained:
                mean, cov = ident.zero
                zero_z.append((mean[2] - height) / np.sqrt(cov[2, 2]))
                truth = derived_at(space, theta)
                worst.append(max(abs(v - truth[k]) / s for k, (v, s) in ident.derived().items()))
        n = args.units
        rows.append([f"{height:g}", f"{min(lifted)}-{max(lifted)}", f"{before} of {n}", f"{after} of {n}",
                     f"{same} of {n}", f"{np.median(zero_z):+.2f}" if zero_z else "-",
                     f"{max(np.abs(zero_z)):.2f}" if zero_z else "-", f"{max(worst):.2f}" if worst else "-"])
    print("# A zero set above first contact (bench/zero_above.py)\n")
    print(f"{args.units} units of {args.sensor} ({args.transfer}) per height, the default 40-pose schedule, the stage "
          f"off by {RIG:g} mm rms, rows of {args.samples} samples; errors in standard errors (the found zero's and "
          "the derived quantities') over the accepted captures.\n")
    print(table(["zero above first contact (mm)", "rows lifted", "accepted before", "accepted now",
                 "rows taken = rows lifted", "zero found, dz error (median)", "zero found, worst |dz error|",
                 "worst derived quantity"], rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
