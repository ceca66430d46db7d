"""Whether identify's standard errors are as wide as its errors: over many units, and on one unit captured again and
again. Units of the paper's drawing (UnitSpace draws, seed k for unit k, as bench/zero_above.py draws them), the
default 40-pose schedule, the stage off by 0.01 mm rms, rows of 128 samples; the schedule whole and without its 16
shallow rows (those that press 0.039 mm: the rows a zero set above first contact lifts off the skin).

Part 1, over units: each derived quantity's error (the magnet's offset from the elements' centre, each element's
sensitivity) in its standard error; how many lie within 1 and 2 (a normal's 68 % and 95 %), their rms, the worst.

Part 2, one unit (--unit, default 1: the worst of part 1 without the shallow rows) captured --repeats times, new
stage errors and noise each time: per derived quantity, the mean error over the captures in standard errors (a
maximum a posteriori is pulled toward the drawing where a capture pins a direction weakly: the prior's share), the
spread of the estimates against the median standard error, and how often 1 standard error covered the truth.

    python bench/repeat_captures.py                      # 154 s here
    python bench/repeat_captures.py --units 10 --repeats 10   # a quick look
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from benchutil import log, parser, table  # noqa: E402
from fitgen.fitting.identify import derived_at, derived_quantities, identify  # noqa: E402
from fitgen.fitting.schedule import schedule  # noqa: E402
from fitgen.physics.pose import OFF_SKIN_MM, off_skin  # noqa: E402
from fitgen.physics.sensor import load_sensor  # noqa: E402
from fitgen.physics.units import UnitSpace  # noqa: E402

RIG = 0.01  # mm rms per axis
SAMPLES = 128
DESIGNS = ("whole", "without the shallow rows")


def capture(space, theta, poses, noise, rng):
    """Readings of the unit ``theta`` at ``poses`` through a stage off by RIG in the rows in contact."""
    true = poses.copy()
    contact = ~off_skin(poses)
    true[contact, :3] += rng.normal(0.0, RIG, (int(contact.sum()), 3))
    return space.readings(theta[None], true)[0] + rng.normal(0.0, noise, (len(poses), space.drawing.n_elements))


def errors(space, theta, y, poses, noise, keep) -> tuple[np.ndarray, np.ndarray]:
    """identify on the rows ``keep``: each derived quantity's estimate less the truth, and its standard error."""
    derived = identify(space.drawing, y[keep], poses[keep], noise, rig_error=RIG).derived()
    truth = derived_at(space, theta)
    return np.array([[v - truth[k], s] for k, (v, s) in derived.items()]).T


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--units", type=int, default=60, help="units in part 1 (default 60)")
    ap.add_argument("--unit", type=int, default=1, help="part 2's unit (default 1)")
    ap.add_argument("--repeats", type=int, default=40, help="part 2's captures (default 40)")
    ap.add_argument("--samples", type=int, default=SAMPLES, help=f"samples per row (default {SAMPLES})")
    args = ap.parse_args(argv)
    if min(args.units, args.repeats, args.samples) < 1 or args.unit < 0:
        ap.error("--units, --repeats and --samples must be >= 1, --unit >= 0")
    drawing = load_sensor("paper").with_transfer("gmr")
    space = UnitSpace.of(drawing)
    noise = drawing.noise / np.sqrt(args.samples)
    poses = schedule(drawing, 40, noise=noise)[0]
    shallow = ~off_skin(poses) & (poses[:, 2] > -OFF_SKIN_MM)
    keeps = {DESIGNS[0]: np.ones(len(poses), dtype=bool), DESIGNS[1]: ~shallow}
    names = list(derived_quantities(space))

    rows = []
    for design, keep in keeps.items():
        z = []
        for seed in range(args.units):
            rng = np.random.default_rng(seed)
            theta = space.draw(rng)
            e, s = errors(space, theta, capture(space, theta, poses, noise, rng), poses, noise, keep)
            z.append(e / s)
            log(f"part 1, {design}: unit {seed}, worst {np.abs(z[-1]).max():.2f} se")
        a = np.abs(np.array(z))
        worst = np.unravel_index(a.argmax(), a.shape)
        rows.append([design, str(int(keep.sum())), f"{np.mean(a < 1):.0%}", f"{np.mean(a < 2):.1%}",
                     f"{np.sqrt(np.mean(a ** 2)):.2f}", f"{a.max():.2f} (unit {worst[0]}, {names[worst[1]]})"])

    theta = space.draw(np.random.default_rng(args.unit))
    truth = derived_at(space, theta)
    off = np.array([truth[n] for n in names]) - [0.0 if n.startswith("magnet") else 1.0 for n in names]
    part2 = []
    for design, keep in keeps.items():
        e, s = [], []
        for r in range(args.repeats):
            ei, si = errors(space, theta, capture(space, theta, poses, noise, np.random.default_rng(10_000 + r)),
                            poses, noise, keep)
            e.append(ei)
            s.append(si)
            log(f"part 2, {design}: capture {r + 1} of {args.repeats}")
        e, s = np.array(e), np.array(s)
        se = np.median(s, axis=0)
        for j in np.argsort(-np.abs(e.mean(axis=0)) / se)[:4]:  # the quantities the prior pulls hardest
            part2.append([design, names[j], f"{off[j]:+.4g}", f"{e[:, j].mean() / se[j]:+.2f}",
                          f"{e[:, j].std(ddof=1) / se[j]:.2f}", f"{np.mean(np.abs(e[:, j]) < s[:, j]):.0%}"])
        toward = np.sign(e.mean(axis=0)) != np.sign(off)
        part2.append([design, f"all {len(names)}: median, and how many pulled toward the drawing",
                      f"{toward.sum()} of {len(names)}", f"{np.median(np.abs(e.mean(axis=0)) / se):.2f}",
                      f"{np.median(e.std(axis=0, ddof=1) / se):.2f}", f"{np.mean(np.abs(e) < s):.0%}"])

    print("# identify's standard errors against its errors (bench/repeat_captures.py)\n")
    print(f"paper (gmr), the default 40-pose schedule, the stage off by {RIG:g} mm rms, rows of {args.samples} "
          f"samples.\n\n## Over {args.units} units (seeds 0-{args.units - 1}), {len(names)} derived quantities "
          "each, errors in standard errors\n")
    print(table(["schedule", "rows", "within 1 se", "within 2 se", "rms", "worst"], rows))
    print(f"\n## Unit {args.unit} captured {args.repeats} times: the four quantities pulled hardest\n")
    print(table(["schedule", "quantity", "truth less the drawing", "mean error (se; all: median of its size)",
                 "spread of estimates / se", "within 1 se"], part2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
