"""The ``fitgen`` command: a thin layer that parses arguments and calls the library."""

from __future__ import annotations

import sys
from pathlib import Path

from . import __version__
from .cliutil import Parser, parse_assignments, run
from .errors import InputError
from .pose import POSE_NAMES


def _sensor(args):
    from .sensor import load_sensor

    sensor = load_sensor(args.sensor)
    if getattr(args, "transfer", None):
        sensor = sensor.with_transfer(args.transfer)
    return sensor


def _noise(value: str, sensor) -> float:
    if value == "sensor":
        return sensor.noise
    try:
        noise = float(value)
    except ValueError:
        raise InputError(f"--noise must be a number or 'sensor', got {value!r}") from None
    if not noise >= 0:
        raise InputError(f"--noise must be >= 0, got {value}")
    return noise


def cmd_simulate(args) -> int:
    from .dataset import load_poses
    from .simulate import PAPER_GRIDS, grid_poses, parse_grid, parse_ranges, pose_rng, random_poses, simulate

    sensor = _sensor(args)
    chosen = [x for x in (args.grid, args.random, args.poses) if x is not None]
    if len(chosen) > 1:
        raise InputError("give one of --grid, --random, --poses")
    if args.poses:
        poses, source = load_poses(args.poses), {"poses_file": str(args.poses)}
    elif args.random is not None:
        poses = random_poses(args.random, parse_ranges(args.ranges), pose_rng(args.seed))
        source = {"random": args.random, "ranges": args.ranges}
    else:
        grid = args.grid or "paper-sim"
        poses, source = grid_poses(parse_grid(grid)), {"grid": grid if grid in PAPER_GRIDS else grid}
    ds = simulate(sensor, poses, noise=_noise(args.noise, sensor), adc_bits=args.adc_bits,
                  seed=args.seed, provenance=source)
    ds.save(args.output)
    print(f"wrote {ds.n_rows} rows x {len(ds.columns)} columns ({sensor.name}, {sensor.transfer}) to {args.output}",
          file=sys.stderr)
    return 0


def cmd_observe(args) -> int:
    from .observe import observe
    from .scenes import load_scene
    from .simulate import parse_ranges

    if args.sensor_pos and args.sensor:
        raise InputError("give the sensor once (positional or --sensor)")
    args.sensor = args.sensor_pos or args.sensor or "paper"
    sensor = _sensor(args)
    scene = load_scene(args.scene)
    ranges = parse_ranges(args.ranges) if args.ranges else scene.ranges
    noise = None if args.noise is None else _noise(args.noise, sensor)
    accuracy = parse_assignments(args.accuracy, POSE_NAMES, "--accuracy") if args.accuracy else None
    report = observe(sensor, ranges, scene.outputs, noise=noise, accuracy=accuracy)
    print(f"sensor {sensor.name} ({sensor.n_elements} elements, {sensor.transfer}), scene {scene.name}")
    print(report.text(), end="")
    return 0


def cmd_demo(args) -> int:
    from .demo import run_demo

    return run_demo(Path(args.out))


def build_parser() -> Parser:
    p = Parser(prog="fitgen", description=__doc__)
    p.add_argument("--version", action="version", version=f"fitgen {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)

    s = sub.add_parser("simulate", help="simulate element readings for a pose set")
    s.add_argument("--sensor", default="paper", help="preset name or sensor TOML (default: paper)")
    s.add_argument("--grid", help="paper-sim, paper-exp, or 'dx=-2:2:5 dz=0,-1 ...'")
    s.add_argument("--random", type=int, metavar="N", help="N random poses in --ranges")
    s.add_argument("--ranges", help="box for --random: 'dx=-2:2 thx=-5:5 ...' (default: paper-sim box)")
    s.add_argument("--poses", metavar="FILE.csv", help="simulate the poses in this CSV")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--noise", default="0", help="element noise rms in output units, or 'sensor' (default 0)")
    s.add_argument("--adc-bits", type=int, help="override the transfer's ADC bits (0: no quantisation)")
    s.add_argument("--transfer", choices=("raw", "gmr"), help="override the sensor file's transfer")
    s.add_argument("-o", "--output", required=True, help="dataset CSV to write")
    s.set_defaults(func=cmd_simulate)

    o = sub.add_parser("observe", help="observability of each pose component (Jacobian SVD, Cramer-Rao)")
    o.add_argument("sensor_pos", nargs="?", metavar="SENSOR")
    o.add_argument("--sensor", help="preset name or sensor TOML (default: paper)")
    o.add_argument("--scene", help="full, slide, press or a scene TOML (default: full)")
    o.add_argument("--ranges", help="pose box 'dx=-2:2 ...' overriding the scene's")
    o.add_argument("--noise", help="element noise rms in output units (default: the sensor file's)")
    o.add_argument("--accuracy", help="required 1-sigma accuracy, e.g. 'dx=0.05 thx=0.5'")
    o.add_argument("--transfer", choices=("raw", "gmr"))
    o.set_defaults(func=cmd_observe)

    d = sub.add_parser("demo", help="the main job end to end on the paper sensor")
    d.add_argument("--out", default="demo-out", help="folder for the demo's files (default: demo-out)")
    d.set_defaults(func=cmd_demo)
    return p


def _main(argv) -> int:
    args = build_parser().parse_args(argv)
    if getattr(args, "adc_bits", None) is not None and not 0 <= args.adc_bits <= 32:
        raise InputError(f"--adc-bits must be 0..32, got {args.adc_bits}")
    return args.func(args)


def main(argv=None) -> int:
    sys.exit(run(_main, argv, "fitgen"))
