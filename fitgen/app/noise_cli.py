"""``tactile-host noise``: does the resting sensor's noise average down, and over how many samples per row?
A thin layer over host.noiserun and host.allan."""

from __future__ import annotations

import sys

from fitgen.app.cliutil import EXIT_CHECK_FAILED, StopFlag
from fitgen.base.fileio import write_all


def cmd_noise(args) -> int:
    from fitgen.app import plots
    from host.adc import DeviceSilent
    from host.noiserun import record_text, run_noise, table, verdict

    folder = plots.require(args.plot) if args.plot else None
    try:
        with StopFlag() as stop:
            av = run_noise(args, stop)
    except DeviceSilent as exc:
        print(f"tactile-host noise: error: {exc}; nothing written", file=sys.stderr)
        return EXIT_CHECK_FAILED
    print(f"tactile-host noise: {av.samples} samples of every element in {av.samples / av.rate:.1f} s "
          f"({av.rate:.0f} per s), the sensor at rest")
    print(table(av))
    print(verdict(av, None if stop.stopped else args.output))  # a stopped run's record is not written
    if stop.stopped:  # a recording cut short would replace a whole one with a verdict on too few samples
        said, status = stop.ended_by()
        print(f"tactile-host noise: {said}: {av.samples} samples so far; nothing written (run it to the end to "
              "write a record)", file=sys.stderr)
        return status
    files = [(args.output, record_text(av, f"simulated {args.sensor}" if args.simulate else "hardware"))
             ] if args.output else []
    if folder is not None:
        files.append((folder / "allan.png", plots.allan_png(av)))
    for path in write_all(files):  # both or neither: a Ctrl-C between them left a new record beside an old plot
        print(f"wrote {path}", file=sys.stderr)
    return 0


def add_noise(sub, adc_options) -> None:
    """The ``noise`` subcommand under ``sub``; ``adc_options(parser)`` adds the bus options read and capture take."""
    from host.noiserun import SECONDS

    n = sub.add_parser("noise", help="read the resting sensor for a while: does its noise average down, and over "
                                     "how many samples per row (the Allan deviation, the flicker floor)?")
    adc_options(n, sensor_help="sensor preset or TOML file: what --simulate simulates (default paper)",
                thermistor=False)
    n.add_argument("--seconds", default=str(SECONDS), help=f"how long to read, s (default {SECONDS:g}: at two "
                   "ADS1115s' rate, long enough to tell 128 samples per row safe where the noise is white)")
    n.add_argument("--simulate", action="store_true", help="no hardware: the simulated sensor at rest")
    n.add_argument("-o", "--output", metavar="NOISE.json", help="write the Allan deviations and the verdict here")
    n.add_argument("--plot", metavar="FOLDER", help="write allan.png here: each element's Allan deviation")
    n.set_defaults(func=cmd_noise)
