"""The input scale of a fixed-point plan, the value of one ADC code, when the user names none: the ADC of the
sensor the model was fitted for, as the fit's fixed-point figures took it."""

from __future__ import annotations

from fitgen.base.errors import InputError
from fitgen.equations.fixedpoint import build_fixed
from fitgen.equations.fixedmodel import FixedModel
from fitgen.equations.model import Model


def default_input_scale(model: Model) -> tuple[float, float, str]:
    """(lsb, offset, where from) of the model's input codes when the user gives none.

    The ADC the fit's fixed-point figures were computed at (:func:`fitted_input_scale`); for a model whose
    record names no sensor and inputs in V, the paper sensor's 16-bit ADC over 0..3.3 V; otherwise an
    InputError asking for ``--input-lsb``.
    """
    found = fitted_input_scale(model)
    if found is not None:
        return found
    rec = model.fit_info.get("held_out") if isinstance(model.fit_info, dict) else None
    if isinstance(rec, dict) and isinstance(rec.get("sensor"), str):  # its ADC may be any: not guessed
        raise InputError(f"fixed point needs the value of one ADC code: the model was fitted on sensor "
                         f"{rec.get('sensor_file') or rec['sensor']}, not found here as it was; give --input-lsb (in "
                         f"{model.input_units})")
    if model.input_units == "V":
        return 3.3 / 65535, 0.0, "default 16-bit ADC over 0..3.3 V"
    raise InputError(f"fixed point needs the value of one ADC code: give --input-lsb (in {model.input_units})")


def fitted_input_scale(model: Model) -> tuple[float, float, str] | None:
    """(lsb, offset, where from) of the ADC the fit took the model's fixed-point figures at
    (:func:`sensor_input_scale` of its sensor): the sensor its held-out record names, where found here
    unchanged (a sensor file too), else the preset whose hash the fit notes give; None when neither is."""
    from fitgen.physics.sensor import load_sensor, preset_names
    from fitgen.physics.simulate import dataset_sensor, with_adc_bits

    info = model.fit_info if isinstance(model.fit_info, dict) else {}
    rec = info.get("held_out")
    if isinstance(rec, dict) and isinstance(rec.get("sensor"), str):
        try:
            held = dataset_sensor(rec)
            if held is not None and rec.get("adc_bits") is not None:  # simulate --adc-bits's ADC, not the file's
                held = with_adc_bits(held, rec["adc_bits"])
        except InputError:  # a recorded file that no longer reads as a sensor, bits that are none
            held = None
        if held is not None and held.units == model.input_units:
            lsb, offset, what = sensor_input_scale(held)
            return lsb, offset, f"sensor {rec.get('sensor_file') or rec['sensor']} ({held.transfer}: {what})"
    sha = info.get("sensor_sha256")
    if isinstance(sha, str):
        for name in preset_names():
            base = load_sensor(name)
            for kind in ("gmr", "raw"):
                s = base.with_transfer(kind)
                # a capture simulated on a preset records its hash whatever its readings are in: a code of the
                # preset's mT had been taken as a code of the capture's volts
                if s.sha256 == sha and s.units == model.input_units:
                    lsb, offset, what = sensor_input_scale(s)
                    return lsb, offset, f"sensor {name} ({kind}: {what})"
    return None


def plan_at(model: Model, input_lsb: float | None = None, input_offset: float | None = None,
            mul_bits: int = 32) -> tuple[FixedModel, str]:
    """The fixed-point plan at the given input scale, and where the scale came from.

    Without ``input_lsb``: the model's own (:func:`default_input_scale`; ``input_offset`` still
    overrides its offset). With it: that LSB and ``input_offset`` (default 0). ``mul_bits``: as for
    :func:`build_fixed` (fitgen.c.targets gives a target's).
    """
    source = "--input-lsb"
    if input_lsb is None:
        input_lsb, default_offset, source = default_input_scale(model)
        input_offset = default_offset if input_offset is None else input_offset
    return build_fixed(model, input_lsb, input_offset or 0.0, mul_bits), source


FIXED_BITS = 16  # ADC bits assumed for fixed point when the sensor's transfer does not quantise


def sensor_input_scale(sensor) -> tuple[float, float, str]:
    """(lsb, offset, description) of the input codes for fixed point: the ADC of the sensor's
    transfer, or FIXED_BITS bits over its range when the transfer does not quantise."""
    if sensor.transfer == "gmr":
        g = sensor.gmr
        bits = g.adc_bits or FIXED_BITS
        lsb, offset, span = (g.adc_max - g.adc_min) / (2**bits - 1), g.adc_min, f"{g.adc_min:g}..{g.adc_max:g} V"
    else:
        r = sensor.raw
        bits = r.adc_bits or FIXED_BITS
        lsb, offset, span = r.full_scale / (2**bits - 1), 0.0, f"0..{r.full_scale:g} mT"
    src = "the transfer's ADC" if (sensor.gmr.adc_bits if sensor.transfer == "gmr" else sensor.raw.adc_bits) \
        else "assumed: the transfer has no ADC"
    return lsb, offset, f"{bits}-bit codes over {span} (LSB {lsb:.4g} {sensor.units}; {src})"
