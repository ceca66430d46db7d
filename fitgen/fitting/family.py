"""The candidate family ``auto``: fit the paper's powers and the harmonics family, keep the one more
accurate as deployed on validation poses.

Validation poses are random poses in the training box, simulated with the sensor and its noise
(seed VALIDATION_SEED, not the held-out seed of fitgen.fitting.holdout), evaluated in float as the device
computes: the figures the model file reports stay held out from this choice. The harmonics family
wins when the geometric mean over outputs of its noisy RMS error over the powers' is below 1.
It is not tried when the elements' positions are unknown or the readings' sum is not > 0.
The two fits share their compressed rows (fitgen.fitting.shared): each family's model is the one it gets
fitted alone, to rounding, at little more than the cost of the larger family's fit.

Every fit for float or fixed point with a sensor at hand (auto or a named family) is then checked on
noise-free validation poses: where the device's rounding adds more than ROUNDING_SHARE of the double model's
max error to an output, it is fitted again with the rounding noise doubled (at most ROUNDING_RETRIES times).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from fitgen.base.errors import InputError, is_whole_number, shown
from fitgen.physics.dataset import Dataset
from fitgen.fitting.fit import FitSettings, fit_model, noise_to_add, ring_harmonics
from fitgen.fitting.holdout import N_POSES, box_of, deployed_errors, held_out_set
from fitgen.equations.model import Model
from fitgen.physics.pose import POSE_NAMES
from fitgen.physics.simulate import other_sensor_problem, with_adc_bits
from fitgen.fitting.shared import SharedRows
from fitgen.equations.terms import FAMILIES, FIXED_FAMILIES, HARMONIC_DEGREE, candidate_terms

VALIDATION_SEED = 7919
VALIDATION_POSES = 1000
VALIDATION_DRAWS = 2
CANDIDATES = ("all", "harmonics")
# verify's gate (fitgen.c.verify, --max-share) fails a header whose rounding adds more than 5 % of the model's
# own held-out max error. ROUNDING_FACTOR (fitgen.fitting.augment) holds it on the drawings' rings, not on a built
# unit's: its symmetry gone, the equations take three times the terms, and on 4 units of 8 an output's share was
# 5-9 %, 1-5 % with the factor doubled, at the same deployed error. A max over 2,000 other poses falls on either
# side of the held-out one: the validation's limit is under the gate.
ROUNDING_SHARE = 0.04
ROUNDING_RETRIES = 2


def candidates(precision: str | None) -> tuple[str, ...]:
    """The families ``auto`` compares for a target precision (the first is the fallback)."""
    return FIXED_FAMILIES if precision == "fixed" else CANDIDATES


def validation_rms(model: Model, sensor, ranges: dict, precision: str = "float") -> dict[str, float]:
    """Per output: RMS error on noisy validation readings, evaluated as the device computes (float
    emulation, or fixed point at the sensor's ADC scale)."""
    val = held_out_set(sensor, ranges, model.output_names, n=VALIDATION_POSES, seed=VALIDATION_SEED,
                       draws=VALIDATION_DRAWS)
    if precision == "fixed":
        from fitgen.equations.fixedpoint import build_fixed
        from fitgen.equations.inputscale import sensor_input_scale

        lsb, offset, _ = sensor_input_scale(sensor)
        est = build_fixed(model, lsb, offset).predict_values(val.noisy)[0]
    elif model.float_problem():  # it cannot run in float: the other family is chosen (or fit refuses both)
        return {}
    else:
        est = model.predict(val.noisy, precision="float")
    with np.errstate(over="ignore", invalid="ignore"):  # an equation far off in float: a huge RMS, said as it is
        err = est - val.noisy_truth
        return {o: float(np.sqrt(np.mean(err[:, j] ** 2))) for j, o in enumerate(model.output_names)}


def rounding_shares(model: Model, sensor, ranges: dict, precision: str) -> dict[str, float]:
    """Per output: the device's rounding's share of the double model's max error (fitgen.fitting.holdout's
    deployed_errors) on noise-free validation readings; {} where the model cannot run in ``precision``."""
    val = held_out_set(sensor, ranges, model.output_names, n=N_POSES, seed=VALIDATION_SEED, draws=1)
    got = deployed_errors(model, val, sensor, precisions=(precision,))[precision]
    return {} if "unavailable" in got else {o: e["share"] for o, e in got.items()}


def rounding_checked(fit_once, ds: Dataset, settings: FitSettings, sensor, again=None) -> tuple[Model, dict]:
    """``fit_once(settings)`` -> (model, family record), fitted again with twice the rounding noise while the
    device's rounding's share on validation poses passes ROUNDING_SHARE (:func:`rounding_shares`); the record
    says so under "rounding". ``again(factor)`` is told before each fit taken again."""
    model, info = fit_once(settings)
    if settings.precision not in ("float", "fixed") or sensor is None or sensor.n_elements != ds.n_inputs:
        return model, info
    ranges = box_of(ds.poses())
    shares, tried = rounding_shares(model, sensor, ranges, settings.precision), []
    while shares and max(shares.values()) > ROUNDING_SHARE and len(tried) < ROUNDING_RETRIES:
        worst = max(shares, key=shares.get)
        tried.append(f"{worst}'s {shares[worst]:.1%} at {settings.rounding_factor:g} u")
        settings = replace(settings, rounding_factor=2 * settings.rounding_factor)
        if again is not None:
            again(settings.rounding_factor)
        model, info = fit_once(settings)
        shares = rounding_shares(model, sensor, ranges, settings.precision)
    if tried:
        info = {**info, "rounding": {
            "factor": settings.rounding_factor, "share": max(shares.values()) if shares else None,
            "why": f"the {settings.precision} rounding's share of the error on validation poses ({N_POSES} poses, "
                   f"seed {VALIDATION_SEED}, noise-free) was over {ROUNDING_SHARE:.0%} ({'; '.join(tried)}): fitted "
                   f"for rounding noise of {settings.rounding_factor:g} unit roundoffs per term"
                   + (f", {max(shares.values()):.1%}" if shares else "")}}
    return model, info


def shared_rows(ds: Dataset, families, settings: FitSettings, sensor) -> SharedRows:
    """The rows the candidate families' fits share (fitgen.fitting.shared): their terms without d have the same
    data and noise rows, compressed once for all of them."""
    harmonics, positive = ring_harmonics(ds, sensor), ds.inputs.min(axis=0) > 0
    scope = [t for f in families for t in candidate_terms(
        ds.n_inputs, "dx", exponents=settings.with_family(f).exponents, d_terms=False, positive=positive,
        harmonics=harmonics, harmonic_degree=settings.with_family(f).harmonic_degree)]
    return SharedRows(ds.inputs, noise_to_add(ds, settings, sensor)["added"], harmonics, scope, ds.targets)


def fit_auto(ds: Dataset, outputs, settings: FitSettings, sensor, progress=None, again=None) -> tuple[Model, dict]:
    """The model of the better family, and the record of the choice (``fit_info["family"]``), its rounding
    checked (:func:`rounding_checked`).

    The families compared are those the target precision can run (:func:`candidates`); ``again``: see
    :func:`rounding_checked`."""
    cands = candidates(settings.precision)
    if sensor is None or sensor.n_elements != ds.n_inputs:
        return fit_model(ds, outputs, settings.with_family(cands[0]), progress, sensor), {
            "name": cands[0], "auto": True, "why": "the elements' positions are unknown (no sensor)"}
    if "harmonics" in cands and not np.sum(ds.inputs.min(axis=0)) > 0:
        record = {"name": "all", "auto": True, "why": "the readings' sum is not > 0 over the data's domain"}
        return rounding_checked(lambda s: (fit_model(ds, outputs, s.with_family("all"), progress, sensor), record),
                                ds, settings, sensor, again)
    forward = None
    if settings.refine:
        from fitgen.fitting.refine_fit import check_refinable, fit_forward

        # the forward model depends on the data alone: one fit serves both families' refinements
        wanted = POSE_NAMES if outputs is None else tuple(n for n in POSE_NAMES if n in outputs)
        check_refinable(ds, wanted, settings.refine, settings.refine_terms)
        forward = fit_forward(ds, max_terms=settings.refine_terms, progress=progress)
    return rounding_checked(lambda s: _compared(ds, outputs, s, sensor, cands, forward, progress), ds, settings,
                            sensor, again)


def _compared(ds: Dataset, outputs, settings: FitSettings, sensor, cands, forward, progress) -> tuple[Model, dict]:
    """:func:`fit_auto`'s comparison of the families ``cands`` at these settings."""
    shared = shared_rows(ds, cands, settings, sensor)
    models = {f: fit_model(ds, outputs, settings.with_family(f), progress, sensor, forward, shared) for f in cands}
    ranges = box_of(ds.poses())
    precision = "fixed" if settings.precision == "fixed" else "float"
    rms = {f: validation_rms(m, sensor, ranges, precision) for f, m in models.items()}
    base, other = cands
    label = {"all": "the powers'", "harmonics": "harmonics'", "no-roots": "no-roots'", "integer": "integer's"}
    if not (rms[base] and rms[other]):  # an empty record: that family's equations cannot run in float
        name = other if rms[other] else base
        lost = base if name == other else other
        return models[name], {"name": name, "auto": True, "validation_rms": {f: r for f, r in rms.items() if r},
                              "why": f"{label[lost]} equations cannot run in float ({models[lost].float_problem()})"}
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # an RMS of 0 or one past float's range
        ratio = float(np.exp(np.mean([np.log(rms[other][o] / rms[base][o]) for o in rms[base]])))
    name = other if ratio < 1 else base
    return models[name], {
        "name": name, "auto": True,
        "why": f"validation ({VALIDATION_POSES} poses, seed {VALIDATION_SEED}, {VALIDATION_DRAWS} noise draws, "
               f"{precision}): {label[other]} RMS error {ratio:.3g}x {label[base]} (geometric mean over outputs)",
        "validation_rms": rms}


def family_settings(family: str, precision: str | None, noise: float | None, refine: int = 0,
                    **more) -> FitSettings:
    """The settings of a fit with ``family`` (``auto``: the first of :func:`candidates`, which
    :func:`fit_auto` may replace) for the device's ``precision`` (None: float, or exact arithmetic
    with ``noise`` 0); ``more``: further FitSettings fields. InputError for a refinement out of
    range and for what fixed point cannot run."""
    from fitgen.equations.refine import MAX_STEPS

    # --noise 0 alone is the paper's procedure (what R's step() computes): no rounding term either
    precision = precision or ("exact" if noise == 0 else "float")
    name = candidates(precision)[0] if family == "auto" else family
    # the rest of --refine's checks (--refine-terms, the data) are fitgen.fitting.refine_fit.check_refinable's
    if not 0 <= refine <= MAX_STEPS:
        raise InputError(f"--refine takes 0 (none) to {MAX_STEPS} steps, got {refine}")
    if precision == "fixed":
        if refine:
            raise InputError("fixed point has no refinement (its Gauss-Newton steps run in float or double): "
                             "drop --refine, or fit for --precision float")
        if name not in candidates("fixed"):
            raise InputError(f"fixed point runs no roots and no harmonic terms, which --family {name} offers: "
                             f"use --family {' or '.join(candidates('fixed'))} (or auto)")
    return FitSettings.family(name, noise=noise, precision=None if precision == "exact" else precision,
                              refine=refine, **more)


def auto_compares(family: str, settings: FitSettings) -> bool:
    """Whether ``family`` is ``auto`` and compares families: noise 0 alone is the paper's procedure,
    its power kinds too, unless fixed point is named."""
    return family == "auto" and (settings.noise != 0 or settings.precision == "fixed")


def fit_family(ds: Dataset, outputs, settings: FitSettings, sensor, family: str,
               progress=None, again=None) -> tuple[Model, dict]:
    """The model fitted with ``family`` (``auto``: :func:`fit_auto` when :func:`auto_compares`), and
    the record of the family (``fit_info["family"]``)."""
    if auto_compares(family, settings):
        return fit_auto(ds, outputs, settings, sensor, progress=progress, again=again)
    record = ({"name": family, "auto": False} if family != "auto" else
              {"name": "all", "auto": True, "why": "--noise 0: the paper's procedure"})
    # the family named is the one fitted and recorded (an unknown one refused), whatever ``settings`` held
    settings = settings.with_family(record["name"])
    return rounding_checked(lambda s: (fit_model(ds, outputs, s, progress=progress, sensor=sensor), record), ds,
                            settings, sensor, again)


def settings_family(settings: FitSettings) -> str:
    """The family ``settings`` name: 'auto' for the default candidates (what `fitgen fit` starts from; they are
    'all''s, so FitSettings.family('all') reads as auto too), else the one of fitgen.equations.terms.FAMILIES whose
    candidates they hold; InputError for candidates of one's own."""
    default = FitSettings()
    if (settings.exponents, settings.harmonic_degree) == (default.exponents, default.harmonic_degree):
        return "auto"
    named = [n for n, e in FAMILIES.items() if (e, HARMONIC_DEGREE.get(n, 0)) == (settings.exponents,
                                                                                   settings.harmonic_degree)]
    if not named:
        raise InputError("the settings' exponents are no named family (fitgen.equations.terms.FAMILIES), which "
                         "fit_device records: give family=, or fit with fit_model")
    return named[0]


def check_dataset_sensor(ds: Dataset, sensor) -> None:
    """InputError when ``sensor`` is not the one ``ds`` was read with, as its meta records it (units, hash): its
    noise would be added to other readings, and figures held out on it would not be the model's."""
    if sensor.n_elements != ds.n_inputs:  # a Dataset made by hand: its noise would be another sensor's
        raise InputError(f"sensor {sensor.name} has {sensor.n_elements} elements; the data have {ds.n_inputs} inputs")
    units = ds.meta.get("units")
    if units in ("mT", "V") and sensor.units != units:
        raise InputError(f"the dataset's readings are in {units}; sensor {sensor.name} reads in {sensor.units} (its "
                         f"{sensor.transfer} transfer): give it with_transfer('{'raw' if units == 'mT' else 'gmr'}')")
    if problem := other_sensor_problem(ds.meta, sensor, sensor.name):
        raise InputError(problem)


def fit_device(ds: Dataset, outputs, settings: FitSettings, sensor, family: str | None = None, *,
               held_out: int = N_POSES, unit_file=None, progress=None, again=None, note=None) -> Model:
    """The model `fitgen fit` writes for dataset ``ds``: :func:`fit_family`'s equations and its record of the family;
    where ``sensor`` is known and ``held_out`` > 0, the held-out record on that many poses
    (fitgen.fitting.holdout.fitted_held_out: on units drawn from the identification's posterior when ``unit_file``
    has one; ``note(text)`` is told what it simulates). ``family``: None for the one ``settings`` name
    (:func:`settings_family`). InputError: a sensor not the dataset's, a bad posterior, before the fit; a float fit
    that float cannot run, after it."""
    from fitgen.fitting.holdout import fitted_held_out, unit_posterior

    family = settings_family(settings) if family is None else family
    if not (is_whole_number(held_out) and held_out >= 0):  # range() of 2.5 inside the held-out set, else
        raise InputError(f"held_out must be a whole number of poses >= 0, got {shown(held_out)}")
    if sensor is not None:
        check_dataset_sensor(ds, sensor)
    hold = bool(held_out) and sensor is not None
    posterior = unit_posterior(unit_file, sensor) if hold else None  # said before the fit's seconds, not after
    # the rows simulate --adc-bits read through that ADC: the fit's validation too (the held-out record's, below)
    read = sensor if sensor is None or ds.meta.get("adc_bits") is None else with_adc_bits(sensor, ds.meta["adc_bits"])
    model, record = fit_family(ds, outputs, settings, read, family, progress, again=again)
    if problem := model.float_problem() if settings.precision == "float" else "":
        raise InputError(f"{problem} (--precision double fits it for double); nothing written")
    model.fit_info["family"] = record
    if hold:
        model.fit_info["held_out"] = fitted_held_out(model, sensor, ds, held_out, unit_file, note=note,
                                                     posterior=posterior)
    return model
