"""Option readers the commands share: the sensor (and its transfer), a noise figure, predict's and codegen's model and
target, fit's settings, the channel map's options, view's checks of --replay and --host."""

from __future__ import annotations

from fitgen.base.errors import InputError, shown
from fitgen.base.parse import MAX_NOISE, MAX_PENALTY, OutOfRange, parse_noise, parse_penalty


def sensor_of(args):
    """``--sensor`` loaded, in ``--transfer`` when given."""
    from fitgen.physics.sensor import load_sensor

    sensor = load_sensor(args.sensor)
    if getattr(args, "transfer", None):
        sensor = sensor.with_transfer(args.transfer)
    return sensor


def sensor_file_of(args) -> dict:
    """``{"sensor_file": its absolute path}`` where ``--sensor`` is a file (a unit's, a drawing of one's own), so that
    the commands after find it from any folder; {} for a preset."""
    from pathlib import Path

    return {"sensor_file": str(Path(args.sensor).resolve())} if Path(args.sensor).is_file() else {}


def noise_of(value: str, sensor, most: float | None = None) -> float:
    """``--noise``: a figure >= 0 (at most ``most``), or ``sensor`` for the sensor's own (which must be > 0: a file
    that leaves it out reads 0, and 'the sensor's noise' would then add none without a word)."""
    if value == "sensor":
        if not sensor.noise > 0:
            from fitgen.physics.transfer import missing_noise

            raise InputError(f"--noise sensor: {missing_noise(sensor)}: add it to the file, or give --noise a figure")
        return sensor.noise
    try:
        x = parse_noise(value)
    except OutOfRange:
        raise InputError(f"--noise must be a finite number >= 0, got {value}") from None
    except ValueError:
        raise InputError(f"--noise must be a number or 'sensor', got {shown(value)}") from None
    if most is not None and x > most:
        raise InputError(f"--noise {value} is no sensor's reading noise (at most {most:g}, in the readings' "
                         "units: V or mT)")
    return x


def model_and_target(args):
    """predict's and codegen's model and target; args.precision the header's: predict computes what codegen writes."""
    from fitgen.c.targets import check_model, check_precision, get_target, header_precision
    from fitgen.equations.model import load_model

    get_target(args.target)  # a bad name said before the model is read
    model = load_model(args.model)
    args.precision = header_precision(args.target, args.precision, model)
    target = check_precision(args.target, args.precision)
    check_model(target, model)
    return model, target


def fit_settings(args):
    """`fitgen fit`'s options (penalty, caps, noise, family) as fit settings; InputError when one is out of range,
    would be ignored, or contradicts another."""
    from fitgen.fitting.family import family_settings

    try:
        k = parse_penalty(args.k)
    except OutOfRange:
        raise InputError(f"--k must be a number > 0 and at most {MAX_PENALTY:g}, got {args.k}") from None
    except ValueError:
        raise InputError(f"--k must be aic, bic or a number > 0, got {args.k!r}") from None
    k = 2.0 if k == "aic" else k
    if args.max_terms is not None and args.max_terms < 1:
        raise InputError(f"--max-terms must be >= 1, got {args.max_terms}")
    if args.refine_terms is not None and args.refine_terms < 5:
        raise InputError(f"--refine-terms must be >= 5 (the five linear terms), got {args.refine_terms}")
    if args.refine_terms is not None and not args.refine:
        raise InputError("--refine-terms caps the forward model of --refine STEPS: without --refine it would be "
                         "ignored")
    if args.true_d and args.no_d_terms:
        raise InputError("--true-d and --no-d-terms contradict each other: --true-d says where the rotations' "
                         "d-terms come from, --no-d-terms leaves them out; give one")
    try:
        noise = None if args.noise is None else parse_noise(args.noise)
    except OutOfRange:
        raise InputError(f"--noise must be a finite number >= 0, got {args.noise}") from None
    except ValueError:
        raise InputError(f"--noise must be a number >= 0 (reading noise rms, input units), got {args.noise!r}") \
            from None
    if noise is not None and noise > MAX_NOISE:  # refused with a meta (its readings overflow), kept without one
        raise InputError(f"--noise {args.noise} is no sensor's reading noise (at most {MAX_NOISE:g}, in the readings' "
                         "units: V or mT)")
    # --refine-terms given or not: FitSettings' own cap (30, as the help says) when not
    cap = {} if args.refine_terms is None else {"refine_terms": args.refine_terms}
    return family_settings(args.family, args.precision, noise, args.refine, k=k, max_terms=args.max_terms,
                           d_terms=not args.no_d_terms, d_source="true" if args.true_d else "estimated", **cap)


def map_options(p, required: bool = True, thermistor: bool = True) -> None:
    """The channel map's options (--adc and the ADCs' settings), as read, view, capture and the builds take
    them. ``thermistor=False``: a command that reads the elements only (its help says so; --thermistor is
    hidden, still parsed so that it is refused in one line)."""
    import argparse

    from host.channelmap import ADS1115_PGA, ADS1115_RATES, MODES

    temp = ("temp=CHIP@ADDRESS:INPUT adds a thermistor, e.g. ...,temp=ads1115@0x4a:0" if thermistor else
            "the elements only: temp= (a thermistor) is refused")
    p.add_argument("--adc", required=required, metavar="SPEC|FILE.toml",
                   help=f"channel map: e.g. ads1115@0x48:0-3,ads1115@0x49:0-3 or ads7828@0x48, or a TOML file; {temp}")
    p.add_argument("--thermistor", metavar="beta=..,r25=..,series=..,vref=..",
                   help="the thermistor's NTC divider (default beta=3950,r25=10000,series=10000,vref=3.3)"
                   if thermistor else argparse.SUPPRESS)
    # no argparse defaults: view --replay tells one typed from one left out (channel_map_from_args fills them in)
    p.add_argument("--pga", type=float, choices=ADS1115_PGA, metavar="V",
                   help="ADS1115 full scale +-V: 6.144, 4.096 (default), 2.048, 1.024, 0.512, 0.256")
    p.add_argument("--data-rate", type=int, choices=ADS1115_RATES, metavar="SPS",
                   help="ADS1115 samples per second: 8..860 (default 860)")
    p.add_argument("--mode", choices=MODES, help="ADS1115 conversion mode (default single)")
    p.add_argument("--vref", help="ADS7828 reference: external volts (default 3.3) or 'internal' (2.5 V)")


# view's options that a replay takes; the others (readout, bus, simulation) would be ignored by it
REPLAY_OPTIONS = ("model", "temp_comp", "auto_zero", "host", "port", "replay", "hold")


def refuse_readout_options(args) -> None:
    """``view --replay``: InputError for the first option given that a replay would ignore (the readout's, the
    bus's, the simulation's: the recording sets the samples)."""
    given = [f"--{n.replace('_', '-')}" for n, value in vars(args).items()  # command, func: argparse's, no options
             if n not in REPLAY_OPTIONS + ("command", "func") and value is not None and value is not False]
    if given:
        raise InputError(f"{given[0]} does not apply to --replay: the recording sets the samples and how they were "
                         "estimated (it plays to its end; --hold keeps the page up after)")


def check_host(host: str) -> None:
    """``view --host``: InputError for ADDRESS:PORT (no address has one colon, IPv6 has two or more) and for an
    address in brackets."""
    import re

    try:
        host.encode("idna")  # as the socket names it; a byte the terminal gave undecoded (\xff) is no address
    except UnicodeError:
        raise InputError(f"--host {host.encode('utf-8', 'replace').decode()!r}: not a host name or address") from None
    m = re.fullmatch(r"\[(.*)\]:(\d+)|([^:]*):(\d+)", host)
    if m:
        address, port = m.group(1) or m.group(3), m.group(2) or m.group(4)
        raise InputError(f"--host {host}: the address only; the port goes in --port (--host {address or '127.0.0.1'} "
                         f"--port {port})")
    if m := re.fullmatch(r"\[(.*)\]", host):  # a URL's form of an IPv6 address; the socket takes it bare
        raise InputError(f"--host {host}: give the address without brackets (--host {m.group(1)})")


def accuracy_of(spec: str | None) -> dict | None:
    """``--accuracy dz=0.05 thx=2``: per pose component a finite number > 0; None when not given."""
    import math

    from fitgen.base.parse import parse_assignments
    from fitgen.physics.pose import POSE_NAMES

    accuracy = parse_assignments(spec, POSE_NAMES, "--accuracy") if spec else None
    for name, value in (accuracy or {}).items():
        if not (math.isfinite(value) and value > 0):
            raise InputError(f"--accuracy {name}={value!r} must be a finite number > 0")
    return accuracy
