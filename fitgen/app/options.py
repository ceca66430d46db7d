"""Option readers the fitgen commands share: the sensor (and its transfer) and a noise figure."""

from __future__ import annotations

from fitgen.base.errors import InputError
from fitgen.base.parse import OutOfRange, parse_noise


def sensor_of(args):
    """``--sensor`` loaded, in ``--transfer`` when given."""
    from fitgen.physics.sensor import load_sensor

    sensor = load_sensor(args.sensor)
    if getattr(args, "transfer", None):
        sensor = sensor.with_transfer(args.transfer)
    return sensor


def noise_of(value: str, sensor) -> float:
    """``--noise``: a figure >= 0, or ``sensor`` for the sensor's own."""
    if value == "sensor":
        return sensor.noise
    try:
        return parse_noise(value)
    except OutOfRange:
        raise InputError(f"--noise must be a finite number >= 0, got {value}") from None
    except ValueError:
        raise InputError(f"--noise must be a number or 'sensor', got {value!r}") from None
