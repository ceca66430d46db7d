"""``tactile-host arduino-build``: an Arduino library for a model, the ReadPose example built for an AVR board (the
Uno by default) and, on request, run on the emulated one. A thin layer over host.arduino and hil.sketch."""

from __future__ import annotations

import sys

from fitgen.app.options import map_options
from fitgen.base.errors import InputError
from host.boards import BOARDS


def cmd_arduino_build(args) -> int:
    from fitgen.equations.model import load_model
    from fitgen.fitting.holdout import device_precision, simulated_sensor_spec
    from fitgen.physics.sensor import load_sensor
    from hil.sketch import build_readpose
    from fitgen.app.report import rounding_note
    from fitgen.equations.fixedpoint import fixed_refusal
    from host.arduino import folder_name_note, headroom_note, lsb_volts, smaller_boards_note
    from host.rest import model_rest
    from host.session import channel_map_from_args
    from host.temperature import thermistor_given

    model, cmap = load_model(args.model), channel_map_from_args(args)
    fitted = device_precision(model)  # as codegen --target uno: the precision fitted for, where an AVR runs it
    args.precision = args.precision or (fitted if fitted in ("float", "fixed") else "float")
    if args.style and args.precision == "fixed":  # fixed point has one layout, as codegen says
        raise InputError("--style does not apply to --precision fixed" + (
            " (the model was fitted for it: give --precision float to build it in float)" if fitted == "fixed" else ""))
    args.style = args.style or "unrolled"
    if args.sim_sensor and args.no_build:  # no emulated run to read it: it would do nothing
        raise InputError("--sim-sensor is the sensor the emulated runs read, and --no-build runs none: drop one")
    lost = ""
    if not args.sim_sensor:
        args.sim_sensor, lost = simulated_sensor_spec(model, "--sim-sensor")
    if thermistor_given(args, cmap):
        raise InputError("the Arduino library reads the elements only, no thermistor: drop temp= from --adc and "
                         "--thermistor (tactile-host read and pi-build read one)")
    simulated = load_sensor(args.sim_sensor)  # a bad one said before the library is written
    if lost and not args.no_build and simulated.n_elements != cmap.n_elements:
        # the build's run at rest (its stack peak) reads it too: the map's error alone had named no missing file
        raise InputError(f"{lost.removeprefix('note: ')} (the sensor the build's emulated runs read, the one at "
                         f"rest that measures the stack too): {args.sim_sensor} has {simulated.n_elements} elements "
                         f"where the channel map reads {cmap.n_elements}")
    if args.rest and not args.tare:
        raise InputError("--rest names what --tare maps the rest readings onto: give --tare too")
    rest, onto = model_rest(model, args.rest) if args.tare else (None, None)
    if lost and args.emulate:  # its lines would read another sensor than the model's, unsaid
        print(f"tactile-host arduino-build: {lost}", file=sys.stderr)
    key = args.board or "uno"  # the note on other boards is for a build none was named for
    size, run = build_readpose(model, cmap, args.output, args.emulate, precision=args.precision, style=args.style,
                               build=False if args.no_build else None, sensor=args.sim_sensor, rest=rest,
                               board=key)
    sys.stdout.write("".join(ln + "\n" for ln in run.lines) if run and args.emulate else "")  # a serial monitor's
    board = BOARDS[key]
    built = (size.describe(board) if size else "not built (--no-build)" if args.no_build
             else "not built (no arduino-builder)")
    print(f"wrote the Arduino library {args.output}; ReadPose for the {board.label}: {built}"
          + (f"; it tares at start onto the rest readings of {onto}" if onto else ""), file=sys.stderr)
    fixed_too = args.precision == "float" and not fixed_refusal(model)
    # the IDE offers every AVR board: where none was named, those the build would not fit
    board_note = "" if args.board else smaller_boards_note(size, "uno", fixed_too)
    for note in (folder_name_note(args.output), board_note, headroom_note(size, board)):
        if note:
            print(note, file=sys.stderr)
    coarse = rounding_note(model, max(lsb_volts(chip) for chip, _ in cmap.elements()))  # a 12-bit ADS7828's
    if coarse:
        print(f"note: {coarse}", file=sys.stderr)
    return 0


def add_arduino_build(sub) -> None:
    """The ``arduino-build`` subcommand under ``sub``."""
    ab = sub.add_parser("arduino-build", help="an Arduino library: the model, the ADC drivers over Wire, the channel "
                                              "map and the ReadPose example; built for an AVR board (the Uno by "
                                              "default) to check it fits")
    ab.add_argument("--model", required=True, metavar="MODEL", help="model file (inputs in V)")
    map_options(ab, thermistor=False)
    ab.add_argument("--precision", choices=("float", "fixed", "double"),
                    help="default: the one the model was fitted for where an AVR runs it (float or fixed), else "
                         "float; double is refused")
    ab.add_argument("--style", choices=("table", "unrolled"),
                    help="the C's form: table (coefficient arrays and a loop) or unrolled (straight-line code; "
                         "default)")
    build = ab.add_mutually_exclusive_group()
    build.add_argument("--no-build", action="store_true", help="write the library only (default: build it when "
                                                            "arduino-builder is installed)")
    build.add_argument("--emulate", metavar="POSE", help="also run ReadPose on the emulated board reading --sim-sensor "
                       "at POSE (e.g. dx=1,dz=-1), its lines on stdout (without it: run at rest, for the stack)")
    ab.add_argument("--sim-sensor", help="the simulated sensor of the emulated runs: --emulate's, and the run at "
                                         "rest that measures the stack whenever simavr is installed (default: the "
                                         "sensor the model was fitted on where its file is found, else paper)")
    ab.add_argument("--board", choices=tuple(BOARDS),
                    help="the board ReadPose is built for and checked against (its flash and RAM as the IDE's "
                         "boards.txt gives them; the stack measured on the emulated ATmega328P or, for the Mega, "
                         "ATmega2560; not on the Leonardo's and Micro's ATmega32U4); default: uno, and a build "
                         "past another board's room is noted")
    ab.add_argument("--tare", action="store_true", help="ReadPose tares at start, onto the model's rest readings")
    ab.add_argument("--rest", metavar="SENSOR|DATASET.csv", help="with --tare: the rest readings it maps onto "
                    "(default: the model's own sensor file where found, else the rest the model recorded)")
    ab.add_argument("-o", "--output", required=True, metavar="DIR", help="the library's folder (e.g. TactilePose)")
    ab.set_defaults(func=cmd_arduino_build)
