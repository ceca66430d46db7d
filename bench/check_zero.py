"""A check capture's zero: reused from the calibration, or set anew. The twin of tests/test_check.py (unit 7 of a
six-element ring, calibrated as the chain does it from a capture whose zero was set by hand 0.02, -0.015 and 0.025
mm off first contact, about one spread of identify's zero error per axis) checked at 30 random poses (fitgen
schedule --check's, seeds 0..), the stage off by 0.01 mm rms, rows of 16 samples, four ways: the calibration's zero
reused; zeroed anew 0.02 mm rms off first contact (one draw per capture, shared by its rows); the sensor moved 0.05
mm and 0.1 mm in dx on its bed (the calibration's zero reused). Per way, how many checks fail (an output beyond 1.5x
every prediction): as fitgen check predicted them before it read where identify found the calibration's zero (at
the labels, zero error 0 for a zero reused and 0.028 mm for one set anew, the two zeros' errors), with
--zero-error 0.02, and as fitgen check predicts them now (fitgen.fitting.check.check_zero: a zero reused stands
the rows at their labels plus the found zero, with its standard error; one set anew has its own error and the
found zero's).

    python bench/check_zero.py              # about 100 s here
    python bench/check_zero.py --checks 10  # a quick look
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from benchutil import log, parser, table  # noqa: E402
from fitgen.fitting.check import check, check_zero  # noqa: E402
from fitgen.fitting.holdout import unit_posterior  # noqa: E402
from fitgen.fitting.schedule import check_schedule  # noqa: E402
from fitgen.physics.simulate import rig_poses  # noqa: E402
from fitgen.physics.transfer import readings  # noqa: E402

ALLOWED = 0.02  # mm rms per axis: what --zero-error allows, and a zero set anew by hand
CALIBRATION_ZERO = np.array([0.02, -0.015, 0.025])  # mm: where the calibration capture's zero sat
BEFORE_ANEW = float(np.hypot(ALLOWED, ALLOWED))  # fitgen check's for a zero set anew, before: both zeros' errors
WAYS = ("the calibration's zero reused", f"zeroed anew, {ALLOWED:g} mm rms off first contact",
        "moved 0.05 mm on its bed", "moved 0.1 mm on its bed")


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--checks", type=int, default=40, help="checks per way (default 40)")
    args = ap.parse_args(argv)
    if args.checks < 1:
        ap.error("--checks must be >= 1")
    import test_check as T  # the tests' twin: the ring, its unit 7 and how it is calibrated

    with tempfile.TemporaryDirectory() as tmp:
        log("the twin: schedule, capture (its zero off first contact), identify, fit")
        folder, drawing, unit, sensor, model = T.make_twin(Path(tmp), CALIBRATION_ZERO)
        posterior = unit_posterior(folder / "twin.toml", sensor)
        reused = check_zero(posterior, T._stage(), "bench")  # what fitgen check now takes, per way
        anew = check_zero(posterior, T._stage(12.05), "bench")
        found = np.array(posterior["zero_found"]["mm"])
        log(f"identify found the zero at {np.round(found, 4).tolist()} mm (set at {CALIBRATION_ZERO.tolist()}); "
            f"fitgen check takes a zero reused with {reused[0]:.2g} mm, one set anew with {anew[0]:.2g} mm")
        zeros = np.random.default_rng(11)
        rows = []
        for way in WAYS:
            failed = {"before": 0, "given": 0, "now": 0}
            for seed in range(args.checks):
                labels, _ = check_schedule(drawing, 30, seed=seed)
                draws = np.random.default_rng(100 + seed)
                zero = CALIBRATION_ZERO if not way.startswith("zeroed") else zeros.normal(0.0, ALLOWED, 3)
                moved = [float(way.split()[1]), 0, 0, 0, 0] if way.startswith("moved") else 0.0
                true = rig_poses(labels + moved, T.RIG, draws, zero)
                y = readings(unit, true, adc_bits=0) + draws.normal(0.0, T.ROW_NOISE, (len(labels), unit.n_elements))
                error, _, at = anew if way.startswith("zeroed") else reused
                before = BEFORE_ANEW if way.startswith("zeroed") else 0.0
                for key, kw in (("before", {"zero_error": before}), ("given", {"zero_error": ALLOWED}),
                                ("now", {"zero_error": error, "zero": at})):
                    c = check(model, y, labels, sensor, T.ROW_NOISE, posterior=posterior, **kw)
                    failed[key] += bool(c.failed())
            log(f"{way}: {', '.join(str(v) for v in failed.values())} of {args.checks} failed")
            rows.append([way] + [f"{v} of {args.checks}" for v in failed.values()])
    print("# A check capture's zero (bench/check_zero.py)\n")
    print(f"tests/test_check.py's twin (unit 7 of a six-element ring) calibrated from a capture whose zero sat "
          f"{', '.join(f'{v:g}' for v in CALIBRATION_ZERO)} mm off first contact (identify found "
          f"{', '.join(f'{v:.3g}' for v in found)}), {args.checks} checks of 30 random poses per way, the stage off "
          "by 0.01 mm rms, rows of 16 samples; a check fails when an output errs beyond 1.5x every prediction.\n")
    print(table(["check capture", f"failed before (at the labels; zero error 0 reused, {BEFORE_ANEW:.3g} anew)",
                 f"failed with --zero-error {ALLOWED:g}",
                 f"failed now (reused: at the found zero, {reused[0]:.2g}; anew: {anew[0]:.3g})"], rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
