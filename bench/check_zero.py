"""A check capture zeroed anew: what `fitgen check --zero-error` buys and costs. The twin of tests/test_check.py (unit
7 of a six-element ring, calibrated as the chain does it) checked at 30 random poses (fitgen schedule --check's,
seeds 0..), the stage off by 0.01 mm rms, rows of 16 samples, four ways: zeroed anew (one draw per capture, shared
by its rows) 0.02 mm rms per axis off the calibration's zero, and 0.028 mm (two zeros each set by hand within 0.02
mm), the sensor moved 0.05 mm and 0.1 mm in dx on its bed (the calibration's zero reused). Per way, how many checks
fail (an output beyond 1.5x every prediction) with no zero error (fitgen check's for a zero reused), with
--zero-error 0.02, and with the 0.028 mm fitgen check takes for a zero set anew by hand from the captures' records.

    python bench/check_zero.py              # about 20 s here
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
from fitgen.fitting.check import check  # noqa: E402
from fitgen.fitting.holdout import unit_posterior  # noqa: E402
from fitgen.fitting.schedule import check_schedule  # noqa: E402
from fitgen.physics.simulate import rig_poses  # noqa: E402
from fitgen.physics.transfer import readings  # noqa: E402

ALLOWED = 0.02  # mm rms per axis: what --zero-error allows
ANEW = float(np.hypot(0.02, 0.02))  # fitgen check's for two zeros set by hand (fitgen.fitting.check.check_zero)


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--checks", type=int, default=40, help="checks per way (default 40)")
    args = ap.parse_args(argv)
    if args.checks < 1:
        ap.error("--checks must be >= 1")
    import test_check as T  # the tests' twin: the ring, its unit 7 and how it is calibrated

    with tempfile.TemporaryDirectory() as tmp:
        log("the twin: schedule, capture, identify, fit")
        folder, drawing, unit, sensor, model = T.make_twin(Path(tmp))
        posterior = unit_posterior(folder / "twin.toml", sensor)
        zeros = np.random.default_rng(11)
        rows = []
        for way in ("zeroed anew, 0.02 mm rms", f"zeroed anew, {ANEW:.3g} mm rms", "moved 0.05 mm on its bed",
                    "moved 0.1 mm on its bed"):
            failed = {0.0: 0, ALLOWED: 0, ANEW: 0}
            for seed in range(args.checks):
                poses, _ = check_schedule(drawing, 30, seed=seed)
                labels = poses
                if way.startswith("zeroed"):
                    draws = np.random.default_rng(100 + seed)
                    true = rig_poses(poses, T.RIG, draws, zeros.normal(0.0, float(way.split()[2]), 3))
                    noise = draws.normal(0.0, T.ROW_NOISE, (len(poses), unit.n_elements))
                    y = readings(unit, true, adc_bits=0) + noise
                else:
                    y = T._capture(unit, poses, 100 + seed)
                    labels = poses + [float(way.split()[1]), 0, 0, 0, 0]
                for allowed in failed:
                    c = check(model, y, labels, sensor, T.ROW_NOISE, posterior=posterior, zero_error=allowed)
                    failed[allowed] += bool(c.failed())
            log(f"{way}: {', '.join(str(v) for v in failed.values())} of {args.checks} failed")
            rows.append([way] + [f"{v} of {args.checks}" for v in failed.values()])
    print("# A check capture zeroed anew (bench/check_zero.py)\n")
    print(f"tests/test_check.py's twin (unit 7 of a six-element ring), {args.checks} checks of 30 random poses per "
          "way, the stage off by 0.01 mm rms, rows of 16 samples; a check fails when an output errs beyond 1.5x every "
          "prediction.\n")
    print(table(["check capture", "failed with zero error 0 (the calibration's zero reused)",
                 f"failed with --zero-error {ALLOWED:g}", f"failed with {ANEW:.3g} (a zero set anew by hand)"], rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
