"""Held-out accuracy of a fitted model, as the device will deliver it (docs/deployed-accuracy.md).

Held out: random poses in the training data's box (a stated seed), never used in fitting,
simulated with the sensor noise-free and with its noise in several draws. Per precision the
device can run, per output: the error noise-free and with noise (max, RMS), the largest
deviation from the double model on noise-free readings, and that deviation's share of the
model's own held-out max error ("rounding's share"). Float is computed by the numpy float32
emulation of the float header (Model.predict(precision="float"), bit-identical to the C built
by gcc on x86-64); fixed point by the numpy model of its integer arithmetic. `tactile-host
verify` and the HIL suite measure the same share on the real C.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fitgen.base.errors import InputError
from fitgen.equations.model import Model
from fitgen.equations.rounding import PRECISIONS
from fitgen.physics.pose import POSE_NAMES
from fitgen.physics.simulate import pose_rng, random_poses, simulate, with_adc_bits
from fitgen.physics.transfer import readings, sensor_hashes

N_POSES = 2000
SEED = 2026
NOISE_DRAWS = 5


@dataclass
class HeldOut:
    """Held-out readings: ``clean`` (n, N) noise-free, ``noisy`` (draws * n, N); targets per row."""

    clean: np.ndarray
    truth: np.ndarray
    noisy: np.ndarray
    noisy_truth: np.ndarray
    spec: dict


def box_of(poses: np.ndarray) -> dict[str, tuple[float, float]]:
    """The box the poses span, per component."""
    return {n: (float(poses[:, j].min()), float(poses[:, j].max())) for j, n in enumerate(POSE_NAMES)}


def held_out_set(sensor, ranges: dict, outputs: tuple[str, ...], *, noise: float | None = None, n: int = N_POSES,
                 seed: int = SEED, draws: int = NOISE_DRAWS, labels: str = "stage", noise_seed: int | None = None
                 ) -> HeldOut:
    """``n`` random poses in ``ranges`` (pose seed ``seed``), simulated with ``sensor``; noise
    draws with seeds noise_seed .. noise_seed + draws - 1 (default noise_seed: seed + 1) at ``noise``
    (default: the sensor's; ``draws`` 0: none). ``labels``: a unit's targets are the stage's
    displacements or the magnet's (fitgen.physics.simulate)."""
    noise = sensor.noise if noise is None else noise
    first = seed + 1 if noise_seed is None else noise_seed
    poses = random_poses(n, ranges, pose_rng(seed))
    cols = [POSE_NAMES.index(o) for o in outputs]
    clean = simulate(sensor, poses, labels=labels).inputs
    noisy = np.vstack([clean[:0]] + [simulate(sensor, poses, noise=noise, seed=first + i, labels=labels).inputs
                                     for i in range(draws)])
    truth = poses[:, cols]
    spec = {"poses": n, "seed": seed, "box": {k: list(v) for k, v in ranges.items()}, "noise": noise, "labels": labels,
            "noise_draws": draws, "noise_seeds": [first, first + draws - 1], "sensor": sensor.name,
            "sensor_sha256": sensor.sha256, "transfer": sensor.transfer}
    return HeldOut(clean, truth, noisy, np.tile(truth, (draws, 1)), spec)


def unit_sets(units: list, ranges: dict, outputs: tuple[str, ...], *, noise: float | None, n: int, seed: int,
              draws: int, labels: str = "stage") -> list[HeldOut]:
    """A held-out set per unit: the same poses, each unit its own ``draws`` noise draws (unit k: seeds
    seed + 1 + k * draws onward). A max over 10,000 noisy readings moves by up to 1.5x from one noise
    realisation to the next (docs/calibration.md); a median over units with their own draws is then a
    median over realisations too, not one realisation's luck shared by every unit."""
    return [held_out_set(u, ranges, outputs, noise=noise, n=n, seed=seed, draws=draws, labels=labels,
                         noise_seed=seed + 1 + k * draws) for k, u in enumerate(units)]


def _fixed_plan(model: Model, sensor):
    """The fixed-point plan at the sensor's ADC scale, or the reason there is none."""
    from fitgen.equations.fixedpoint import build_fixed
    from fitgen.equations.inputscale import sensor_input_scale

    lsb, offset, _ = sensor_input_scale(sensor)
    try:
        return build_fixed(model, lsb, offset)
    except InputError as exc:
        return str(exc)


def estimator(model: Model, precision: str, sensor=None):
    """``model``'s estimates in ``precision`` as the device computes them, a function of readings (n, N); or the
    reason it cannot run in it (fixed point takes the readings' codes at ``sensor``'s ADC scale)."""
    return _estimator(model, precision, sensor)[0]


def _estimator(model: Model, precision: str, sensor=None):
    """:func:`estimator`, and the fixed-point plan it runs (None for double and float)."""
    if precision == "double":
        return model.predict, None
    if precision == "float":
        problem = model.float_problem()
        return problem or (lambda x: model.predict(x, precision="float")), None
    fm = _fixed_plan(model, sensor) if sensor is not None else "no sensor to take the ADC scale from"
    if isinstance(fm, str):
        return fm.splitlines()[0], None
    return (lambda x: fm.to_real(fm.predict_codes(fm.codes_of(x))[0])), fm


def deployed_errors(model: Model, held: HeldOut, sensor=None, precisions=PRECISIONS) -> dict:
    """Per precision, per output: max, rms (noise-free), noisy_max, noisy_rms, deviation (max |this
    precision - double| noise-free) and share (deviation / the double model's max). Fixed point takes
    the readings' ADC codes and is compared with double on the codes' values: its share is the
    arithmetic's, the quantisation stays in its errors. A precision the model cannot be generated in
    gets {"unavailable": reason}."""
    double_clean = model.predict(held.clean)
    model_max = np.abs(double_clean - held.truth).max(axis=0)
    out = {}
    for prec in precisions:
        fn, fm = _estimator(model, prec, sensor)
        if isinstance(fn, str):
            out[prec] = {"unavailable": fn}
            continue
        # fixed point against double on the codes' values: the arithmetic's share, the quantisation's left out
        ref = double_clean if fm is None else model.predict(fm.code_values(fm.codes_of(held.clean)))
        clean, noisy = fn(held.clean), fn(held.noisy)
        e, en = np.abs(clean - held.truth), np.abs(noisy - held.noisy_truth)
        dev = np.abs(clean - ref).max(axis=0)
        out[prec] = {o: {"max": float(e[:, j].max()), "rms": float(np.sqrt(np.mean(e[:, j] ** 2))),
                         "noisy_max": float(en[:, j].max()), "noisy_rms": float(np.sqrt(np.mean(en[:, j] ** 2))),
                         "deviation": float(dev[j]),
                         "share": float(dev[j] / model_max[j]) if model_max[j] > 0 else 0.0}
                     for j, o in enumerate(model.output_names)}
    return out


POSTERIOR_UNITS = 8  # units drawn from an identification's posterior to widen the figures
POSTERIOR_SEED = 2027
FIGURES = ("max", "rms", "noisy_max", "noisy_rms", "deviation", "share")
SPREAD_FIGURES = ("max", "rms", "noisy_max", "noisy_rms")  # their range over the posterior's units is recorded


def over_units(values: list[dict], figures, p90=()) -> dict:
    """One output's figures over units (``values``: each unit's): the median of each of ``figures``, the 90th
    percentile of ``p90``'s, the least (``*_lo``) and greatest (``*_hi``) of SPREAD_FIGURES."""
    out = {f: float(np.median([v[f] for v in values])) for f in figures}
    out.update({f"{f}_p90": float(np.percentile([v[f] for v in values], 90)) for f in p90})
    out.update({f"{f}_{k}": float(fn([v[f] for v in values]))
                for f in SPREAD_FIGURES for k, fn in (("lo", np.min), ("hi", np.max))})
    return out


def evaluate(model: Model, sensor, ranges: dict, *, noise: float | None = None, n: int = N_POSES,
             seed: int = SEED, draws: int = NOISE_DRAWS, posterior: dict | None = None,
             labels: str = "stage") -> dict:
    """The ``held_out`` record of a model file: how it was made and the errors per precision.

    ``posterior`` (an identified unit's record, fitgen.fitting.unitrecord.save): the figures are held out on
    POSTERIOR_UNITS units drawn from it instead of on ``sensor`` alone, and each figure is the median
    over those units (the 90th percentile beside it), so that what the file says includes how well the
    capture pinned the unit down.
    """
    if posterior is None:
        held = held_out_set(sensor, ranges, model.output_names, noise=noise, n=n, seed=seed, draws=draws,
                            labels=labels)
        return {**held.spec, "errors": deployed_errors(model, held, sensor)}
    units = posterior_units(posterior, sensor, POSTERIOR_UNITS)
    sets = unit_sets(units, ranges, model.output_names, noise=noise, n=n, seed=seed, draws=draws, labels=labels)
    per_unit = [deployed_errors(model, held, u) for held, u in zip(sets, units)]
    spec = {**sets[0].spec, "noise_seeds": [sets[0].spec["noise_seeds"][0], sets[-1].spec["noise_seeds"][1]]}
    errors = {}
    for prec, rec in per_unit[0].items():
        if "unavailable" in rec:
            errors[prec] = rec
            continue
        errors[prec] = {o: over_units([u[prec][o] for u in per_unit], FIGURES, p90=("max", "noisy_max"))
                        for o in rec}
    return {**spec, "sensor": sensor.name, "sensor_sha256": sensor.sha256, "errors": errors,
            "posterior": {"units": len(units), "seed": POSTERIOR_SEED,
                          "statistic": "median over units drawn from the identification's posterior (Laplace), "
                                       "each with its own noise draws; *_p90: their 90th percentile (of 8 draws: a unit "
                                       "falls below it about 4 times in 5); *_lo, *_hi: their least and greatest "
                                       "(a unit falls between them 7 times in 9, below *_hi 8 in 9: "
                                       "bench/identify_bound.py)"}}


UNCALIBRATED_UNITS = 8  # units built within a drawing's tolerances, to show what its model does on them uncalibrated
UNCALIBRATED_SEED = 2029


def tolerance_units(drawing, k: int = UNCALIBRATED_UNITS, seed: int = UNCALIBRATED_SEED) -> list:
    """``k`` units of ``drawing`` drawn within its ``[tolerances]`` (as ``fitgen simulate --unit`` draws one); none
    when the tolerances are all 0."""
    from fitgen.physics.units import UnitSpace

    space = UnitSpace.of(drawing)
    if not np.any(space.prior_sd > 0):
        return []
    rng = np.random.default_rng(seed)
    return [space.sensor(space.draw(rng), f"{drawing.name}-built-{i + 1}",
                         f"a unit of {drawing.name} drawn within its tolerances") for i in range(k)]


def device_precision(model: Model) -> str:
    """The precision the model was fitted to run in (double for exact arithmetic)."""
    target = (model.fit_info.get("precision") or {}).get("target") if isinstance(model.fit_info, dict) else None
    return target if target in PRECISIONS else "double"


def uncalibrated(model: Model, drawing, ranges: dict, *, noise: float | None = None, n: int = N_POSES,
                 seed: int = SEED, draws: int = NOISE_DRAWS) -> dict | None:
    """The ``uncalibrated`` record of a model fitted on ``drawing``: its held-out figures, in the precision it was
    fitted for, on UNCALIBRATED_UNITS units built within the drawing's tolerances into which it is flashed as it is
    (no capture, no identify); per output the median over the units, their least and greatest. Targets are the
    stage's displacements, as a capture of such a unit labels them. None when the tolerances are all 0."""
    units = tolerance_units(drawing)
    if not units:
        return None
    prec = device_precision(model)
    per_unit = [deployed_errors(model, held, u, (prec,))[prec]
                for held, u in zip(unit_sets(units, ranges, model.output_names, noise=noise, n=n, seed=seed,
                                             draws=draws), units)]
    if "unavailable" in per_unit[0]:
        return None
    errors = {o: over_units([u[o] for u in per_unit], SPREAD_FIGURES) for o in model.output_names}
    return {"units": len(units), "seed": UNCALIBRATED_SEED, "precision": prec, "errors": errors,
            "statistic": "median over units drawn within the drawing's [tolerances], each with its own noise "
                         "draws, the model flashed into them uncalibrated; *_lo, *_hi: their least and greatest"}


def unit_posterior(unit_file, sensor) -> dict | None:
    """The posterior record ``unit_file`` names (fitgen.fitting.unitrecord.load_posterior), checked as
    :func:`posterior_units` draws from it in ``sensor``'s transfer; None when there is none. InputError for
    one that is missing or bad: read before a fit, so that this is said before the work, not after it."""
    from fitgen.fitting.unitrecord import load_posterior

    posterior = load_posterior(unit_file) if unit_file else None
    if posterior is not None:
        from fitgen.physics.sensor import load_sensor

        if load_sensor(unit_file).with_transfer(sensor.transfer).sha256 != sensor.sha256:  # the drawing, say
            raise InputError(f"sensor {sensor.name} is not the unit {unit_file} describes: give that file's own "
                             "(load_sensor of it), whose posterior this is")
        try:
            space, theta, _ = _posterior_draw(posterior, sensor)
            # its mean is the unit the file describes (identify writes both from one fit): an edited mean
            # would hold the figures out on units about another one, in silence
            poses = np.vstack([np.zeros(5), np.diag([0.5, 0.5, -0.5, 3.0, 3.0])])
            mine, theirs = (readings(u, poses, adc_bits=0) for u in (space.sensor(theta), sensor))
            if not np.allclose(mine, theirs, rtol=1e-6, atol=1e-9 * np.max(np.abs(theirs))):
                raise InputError("the unit's posterior mean (theta) is not the unit its file describes "
                                 "(one of the two edited?): identify again")
        except InputError as exc:
            raise InputError(f"unit file {unit_file}: {exc}") from None
    return posterior


def fitted_held_out(model: Model, sensor, ds, n: int, unit_file=None, note=None, posterior=None) -> dict:
    """The ``held_out`` record of a model fitted to dataset ``ds``: :func:`evaluate` on ``n`` poses in
    the box of its poses, with the device's noise the fit assumed (the sensor's, where it assumed none) and the
    dataset's labels; on units
    drawn from the identification's posterior when ``unit_file`` has one (``posterior``: that record as
    :func:`unit_posterior` read it before the fit; read here when not given). ``note(text)`` is told what
    is simulated."""
    posterior = posterior if posterior is not None else unit_posterior(unit_file, sensor)
    # the deployed figures are with the sensor's noise (conventions.md): a fit for none (--noise 0, the paper's
    # procedure) is still read by a device that has it
    noise = model.fit_info["noise"]["device"] or sensor.noise
    file_sha, bits = sensor.sha256, ds.meta.get("adc_bits")
    if bits is not None:  # simulate --adc-bits: through that ADC, the record naming the file's sensor and the bits
        sensor = with_adc_bits(sensor, bits)
    if note:
        note(f"{n} random poses, {noise or 0:g} noise"
             + (", units from the identification's posterior" if posterior else ""))
    record = evaluate(model, sensor, box_of(ds.poses()), noise=noise, n=n, posterior=posterior,
                      labels=ds.meta.get("labels", "stage"))
    if bits is not None:  # its file found again by that hash (a moved folder; fixed point's codes, with the bits)
        record.update(sensor_sha256=file_sha, adc_bits=bits)
    # what a tare rests on where the sensor's file is not at hand (the model alone copied to a Pi)
    record["rest"] = readings(sensor, np.zeros(5), adc_bits=0)[0].tolist()
    if (spread := rest_spread(sensor, posterior)) is not None:  # what a tare onto another unit's rest would take
        record["rest_spread"] = spread
    if unit_file and Path(unit_file).is_file():  # a unit's, or a drawing of the user's own: verify finds it again
        record["sensor_file"] = str(Path(unit_file).resolve())
        if sensor.is_drawing:  # a record without it, with a file, is a unit's (as models fitted before it say)
            record["drawing"] = True
    if posterior is None and sensor.is_drawing and ds.meta.get("sensor_sha256") == file_sha:
        # the drawing's own model: what it does on the units people build from the drawing, if not calibrated
        if note:
            note(f"{UNCALIBRATED_UNITS} units built within the drawing's tolerances")
        unc = uncalibrated(model, sensor, box_of(ds.poses()), noise=noise, n=n)
        if unc is not None:
            record["uncalibrated"] = unc
    return record


REST_SPREAD_UNITS = 64  # units drawn for the spread of their rest readings
REST_SPREAD_SEED = 2031


def rest_spread(sensor, posterior: dict | None = None) -> list[float] | None:
    """Per input, the spread (standard deviation) of the rest readings over units built within the tolerances of
    the drawing that unit ``sensor`` was built to (its posterior's drawing, else its ``[unit]`` table's): how far
    another unit's rest lies from this one's, which a tare onto this one's would take for offsets. None for a
    drawing, and where the drawing does not load here or has no tolerances."""
    from fitgen.physics.sensor import load_sensor
    from fitgen.physics.units import UnitSpace

    if sensor.is_drawing:
        return None
    unit = sensor.source.get("unit") if isinstance(sensor.source, dict) else None
    spec = (unit.get("drawing_spec") or unit.get("drawing")) if isinstance(unit, dict) else None
    try:
        if posterior is not None:
            space = _posterior_draw(posterior, sensor)[0]
        elif isinstance(spec, str):
            space = UnitSpace.of(load_sensor(spec).with_transfer(sensor.transfer))
        else:
            return None
    except InputError:  # a drawing moved or edited: the fit goes on without what only a tare's note reads
        return None
    if space.drawing.n_elements != sensor.n_elements:
        return None
    return _units_rest_spread(space)


def drawing_rest_spread(drawing) -> list[float] | None:
    """:func:`rest_spread` of the units built within ``drawing``'s tolerances; None where it has none."""
    from fitgen.physics.units import UnitSpace

    return _units_rest_spread(UnitSpace.of(drawing))


def _units_rest_spread(space) -> list[float] | None:
    if not np.any(space.prior_sd > 0):
        return None
    rng = np.random.default_rng(REST_SPREAD_SEED)
    thetas = np.array([space.draw(rng) for _ in range(REST_SPREAD_UNITS)])
    return space.readings(thetas, np.zeros((1, 5)))[:, 0, :].std(axis=0).tolist()


def posterior_units(record: dict, sensor, k: int) -> list:
    """``k`` units drawn from an identification's posterior record, in ``sensor``'s transfer."""
    space, theta, L = _posterior_draw(record, sensor)
    z = np.random.default_rng(POSTERIOR_SEED).standard_normal((k, space.size))
    return [space.sensor(theta + L @ zi, f"{sensor.name}-posterior-{i + 1}") for i, zi in enumerate(z)]


def _posterior_draw(record: dict, sensor):
    """What units are drawn from a posterior record with: its drawing's unit space in ``sensor``'s transfer, the
    mean and a Cholesky factor of the covariance; InputError when the record cannot give them."""
    from fitgen.physics.sensor import load_sensor
    from fitgen.physics.units import UnitSpace

    try:
        spec = str(record["drawing_spec"])
        theta = np.asarray(record["theta"], dtype=float)
        cov = np.asarray(record["covariance"], dtype=float)
    except (KeyError, TypeError, ValueError):
        raise InputError("the unit's posterior record is malformed (expected fitgen identify's)") from None
    back = "put back the file it was identified on (it is looked for beside the unit's file too), or identify again"
    try:
        drawing = load_sensor(spec).with_transfer(sensor.transfer)
    except InputError as exc:  # a drawing's file deleted or moved without the unit's: not a malformed record
        raise InputError(f"the unit's posterior names the drawing it was identified on, {spec}, which does not load "
                         f"here ({exc}): {back}") from None
    sha = record.get("drawing_sha256")
    if isinstance(sha, str) and sha not in sensor_hashes(drawing):
        # its units would be drawn with the edited drawing (another ADC, say) about a unit identified on the old one
        raise InputError(f"the drawing the unit was identified on, {spec}, has changed since (edited, or another "
                         f"drawing now at that path): {back}")
    space = UnitSpace.of(drawing)
    if (theta.shape != (space.size,) or cov.shape != (space.size, space.size)
            or record.get("parameters") != list(space.names)):
        raise InputError(f"the unit's posterior does not fit its drawing {record.get('drawing_spec')!r} (its "
                         "parameters are not the drawing's: its [tolerances] edited since identify?)")
    prior = record.get("prior_sd")
    if isinstance(prior, list) and (len(prior) != space.size or not np.allclose(prior, space.prior_sd, rtol=1e-9,
                                                                                 atol=0.0)):
        raise InputError(f"the drawing the unit was identified on, {spec}, has other [tolerances] than at identify: "
                         f"{back}")
    # identify's lie within a few prior spreads, and no posterior is wider than its prior: past these, an edit
    # (NaN or 1e308 drew units of no field, and check's table of nonsense passed or failed by chance)
    with np.errstate(all="ignore"):
        far = ~(np.abs(theta) <= 20 * space.prior_sd) | ~(np.sqrt(np.abs(np.diag(cov))) <= 2 * space.prior_sd)
    if far.any():
        raise InputError(f"the unit's posterior gives {space.names[int(np.argmax(far))]} a value or spread past any "
                         "identification's (edited by hand?): identify again")
    if not _covariance_ok(cov, space.free):  # edited by hand: no covariance a draw could come from
        raise InputError("the unit's posterior covariance is not symmetric positive definite over the parameters "
                         "that vary between units, 0 elsewhere (expected fitgen identify's)")
    L = np.linalg.cholesky(cov + 1e-12 * np.diag(np.diag(cov)) + 1e-300 * np.eye(space.size))
    return space, theta, L


def _covariance_ok(cov: np.ndarray, free: np.ndarray) -> bool:
    """Whether ``cov`` is a posterior covariance identify could write: finite; 0 in the rows and columns of the
    parameters that do not vary (``free`` False, the prior pins them); over the others, symmetric to rounding
    (identify's is an inverse's: its correlations differ from their transposes by up to 4e-8 on rows of 1,024 samples
    from an exact stage) and positive definite, each with a spread > 0 (the prior bounds it from below)."""
    if not np.all(np.isfinite(cov)) or np.any(cov[~free]) or np.any(cov[:, ~free]):
        return False
    c = cov[np.ix_(free, free)]
    d = np.diag(c)
    if not np.all(d > 0):
        return False
    corr = c / np.sqrt(np.outer(d, d))
    if not np.all(np.abs(corr - corr.T) <= 1e-6):
        return False
    try:  # with the draw's own allowance for rounding (a capture can pin a direction a million times its prior)
        np.linalg.cholesky((corr + corr.T) / 2 + 1e-12 * np.eye(len(corr)))
    except np.linalg.LinAlgError:
        return False
    return True


def fitted_sensor(sensor, model: Model, why: str, flag: str = "--sensor", given: str | None = None):
    """``sensor`` in the transfer that gives ``model``'s units; InputError, ending in ``why``, when the model was
    fitted on another sensor (other units, or a hash in neither transfer, :func:`sensor_hashes`, the one its file
    records), naming it as ``given`` (the file or preset typed), else by its name."""
    if sensor.units != model.input_units and model.input_units in ("mT", "V"):
        sensor = sensor.with_transfer("gmr" if model.input_units == "V" else "raw")
    fitted_on = model.fit_info.get("sensor_sha256")
    if sensor.units != model.input_units or (fitted_on is not None and fitted_on not in sensor_hashes(sensor)):
        raise InputError(f"{flag} {given or sensor.name}: the model was fitted on another sensor "
                         f"({model.input_units} readings{', sensor ' + str(fitted_on)[:12] if fitted_on else ''}); "
                         f"{why}")
    return sensor


def fitted_sensor_spec(model: Model) -> str | None:
    """The preset name or sensor file of the sensor ``model``'s held-out figures are for, where it is found here
    and is still that sensor (by hash); else None."""
    from fitgen.physics.simulate import recorded_spec

    return recorded_spec(model.fit_info.get("held_out") if isinstance(model.fit_info, dict) else None)


def simulated_sensor_spec(model: Model, option: str, default: str = "paper") -> tuple[str, str]:
    """The sensor a simulation for ``model`` runs without being told one: :func:`fitted_sensor_spec`, else
    ``default``; and a note when the model names another sensor (a unit's file) not found here as it was, which
    ``option`` gives ('' otherwise): a silent drawing in a unit's place reads as a unit far from its twin."""
    own = fitted_sensor_spec(model)
    if own:
        return own, ""
    rec = model.fit_info.get("held_out") if isinstance(model.fit_info, dict) else None
    lost = (rec.get("sensor_file") or rec.get("sensor")) if isinstance(rec, dict) else None
    if not isinstance(lost, str) or lost == default:
        return default, ""
    return default, (f"note: the model was fitted on {lost}, not found here as it was: simulating {default}; "
                     f"give {option}")


def names_held_out_set(rec) -> bool:
    """Whether a model's ``held_out`` record names a set to simulate again: its box, poses and seed."""
    return isinstance(rec, dict) and all(key in rec for key in ("box", "poses", "seed"))


def clean_readings(model: Model, sensor=None) -> tuple[np.ndarray, np.ndarray] | None:
    """The noise-free held-out readings and targets the model file's ``held_out`` record names,
    simulated again (with ``sensor``, else the preset it names, checked by hash); None when the
    model has no such record or its sensor cannot be had."""
    from fitgen.physics.simulate import dataset_sensor

    rec = model.fit_info.get("held_out") if isinstance(model.fit_info, dict) else None
    if not names_held_out_set(rec):
        return None  # no record, or one that names no set (a sensor alone)
    if not set(POSE_NAMES) <= set(rec["box"]):
        raise InputError(f"the model file's fit.held_out.box gives no range for "
                         f"{', '.join(o for o in POSE_NAMES if o not in rec['box'])} (fitgen fit gives one for each "
                         "pose component): fit the model again, or go without its held-out check (--no-held-out)")
    sensor = sensor or dataset_sensor(rec)
    if sensor is None:
        return None
    if rec.get("adc_bits") is not None:  # the readings simulate --adc-bits made, read again through that ADC
        sensor = with_adc_bits(sensor, rec["adc_bits"])
    held = held_out_set(sensor, {k: tuple(v) for k, v in rec["box"].items()}, model.output_names,
                        n=int(rec["poses"]), seed=int(rec["seed"]), draws=0, labels=rec.get("labels", "stage"))
    return held.clean, held.truth
