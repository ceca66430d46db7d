"""What answers an emulated board's I2C bridge: a simulated sensor behind simulated ADCs, for a firmware
that reads its inputs through a channel map (``tactile-hil emulate --adc``)."""

from __future__ import annotations

from fitgen.base.errors import InputError


def adc_bridge(adc: str, pose: str, *, sensor: str = "paper", noise: float | None = None, seed: int = 0,
               thermistor: str | None = None, temp_comp: str | None = None, temperature: float | None = None,
               n_inputs: int | None = None):
    """What answers the emulated board's I2C bridge for a firmware reading ``adc`` (a channel map, with an
    optional temp= input): (channel map, a host.pi.StandIn over the simulated bus with ``sensor`` at ``pose``
    on a virtual clock, the thermistor input, the compensation loaded from ``temp_comp``). ``noise``: V rms
    (None: the sensor's); ``temperature``: the sensor held there (typical coefficients, seed ``seed``);
    ``n_inputs``: the model's inputs, which the map must read."""
    from fitgen.physics.sensor import load_sensor
    from host.channelmap import channel_map
    from host.clock import VirtualClock
    from host.motion import parse_pose
    from host.pi import StandIn
    from host.simbus import simulated_bus
    from host.simsensor import Drift
    from host.temperature import load_tempcomp, split_channel_map, temperature_input

    cmap = channel_map(split_channel_map(adc)[0])
    if n_inputs is not None and cmap.n_elements != n_inputs:  # the model's count first: the sensor follows it
        raise InputError(f"the channel map reads {cmap.n_elements} elements; the model takes {n_inputs}")
    tin = temperature_input(adc, cmap, thermistor)
    if tin is None and temp_comp:
        raise InputError("--temp-comp needs the thermistor's input: add temp=CHIP@ADDRESS:INPUT to --adc")
    tempcomp = load_tempcomp(temp_comp) if temp_comp else None
    drift = None
    if temperature is not None:
        # the sensor at a steady temperature: typical temperature coefficients, no creep
        drift = Drift.typical(cmap.n_elements, seed=seed).steady(temperature)
    sim_sensor = load_sensor(sensor)
    if noise is not None and not noise >= 0:  # NaN too
        raise InputError(f"--sim-noise must be >= 0, got {noise}")
    clock = VirtualClock()
    bus = simulated_bus(cmap, sim_sensor, parse_pose(pose), clock=clock, noise=noise, seed=seed, drift=drift,
                        thermistor=tin)
    return cmap, StandIn(bus, clock), tin, tempcomp
