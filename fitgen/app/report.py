"""Accuracy reports: errors per output and per dz level, terms, AIC traces, the paper's numbers beside ours."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fitgen.base.errors import InputError
from fitgen.physics.dataset import Dataset
from fitgen.fitting.fit import error_stats
from fitgen.equations.model import Model
from fitgen.equations.model import MAX_INPUTS

# the seed paper's figures (simulation study on paper-sim, and experiment term counts)
PAPER_SIM_MAX_ERROR = {"dx": 0.06, "dz": 0.25, "thx": 1.23}
PAPER_EXP_TERMS = {"dx": 18, "dz": 21, "thx": 39}


def errors_on(model: Model, ds: Dataset) -> dict:
    """Per output: the model's errors on the rows of ``ds``, overall and per dz level (when it has at most 12)."""
    pred = model.predict(ds.inputs)
    out = {}
    levels = np.unique(ds.target("dz")) if "dz" in ds.target_names else np.array([])
    for j, name in enumerate(model.output_names):
        if name not in ds.target_names:
            continue
        err = pred[:, j] - ds.target(name)
        row = {"all": error_stats(err)}
        if 1 < len(levels) <= 12:
            dz = ds.target("dz")
            row["by_dz"] = {float(v): error_stats(err[dz == v]) for v in levels}
        out[name] = row
    return out


def _table(head: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(head)]
    lines = ["| " + " | ".join(h.ljust(w) for h, w in zip(head, widths)) + " |",
             "| " + " | ".join("-" * w for w in widths) + " |"]
    lines += ["| " + " | ".join(c.ljust(w) for c, w in zip(r, widths)) + " |" for r in rows]
    return "\n".join(lines)


def _g(x: float) -> str:
    return f"{x:.3g}"


def fit_assumptions(info: dict, units: str = "") -> str:
    """One line: the noise (in the inputs' ``units``) and the precision the fit assumed (from a model file's fit
    notes)."""
    noise, prec = info.get("noise"), info.get("precision", {})
    if not isinstance(noise, dict):
        return "fitted for: not recorded (a model file from before noise-aware fitting)"
    u = f" {units}" if units else ""
    dev = ("unknown (no --noise, no sensor, and the capture did not measure it)" if noise.get("device") is None
           else f"{noise['device']:g}{u} rms ({noise.get('device_source', '?')})")
    data = ("not recorded (the rows taken to carry the device's own)" if noise.get("data") is None
            else f"{noise['data']:g}{u}")
    added = noise.get("added", 0)
    why = f" ({noise['why']})" if not added and noise.get("why") else ""
    target = prec.get("target") or "exact arithmetic"
    line = (f"fitted for: reading noise {dev}, data's own noise {data}, added in expectation {added:g}{u}{why}; "
            f"precision {target}")
    fam = info.get("family")
    if isinstance(fam, dict) and "name" in fam:
        line += f"\ncandidates: family {fam['name']}" + (f" (auto: {fam.get('why', '')})" if fam.get("auto") else "")
        if isinstance(fam.get("rounding"), dict):
            line += f"\nrounding: {fam['rounding'].get('why', '')}"
    ref = info.get("refine")
    if isinstance(ref, dict) and "steps" in ref:
        sd = ", ".join(f"{k} {v:.3g}" for k, v in ref.get("prior_sd", {}).items())
        line += (f"\nrefinement: {ref['steps']} Gauss-Newton step(s) after the equations on a forward model "
                 f"({ref['transform']}, {sum(ref['terms'])} terms over {len(ref['terms'])} elements, at most "
                 f"{max(ref['terms'])} each); prior sd about the equations' estimate: {sd}")
    return line


def criterion(fit_info: dict) -> str:
    """The criterion the search minimised, as the model file's settings record its penalty per term: AIC (k = 2),
    BIC (k = log n) or AIC with another k, 'AIC (k = 6)'."""
    import math

    k, n = (fit_info.get("settings") or {}).get("k"), fit_info.get("dataset_rows")
    if not isinstance(k, (int, float)) or k == 2:
        return "AIC"
    if isinstance(n, int) and n > 1 and math.isclose(k, math.log(n)):
        return "BIC"
    return f"AIC (k = {k:.3g})"


def fit_summary(model: Model, held_out: int) -> str:
    """What ``fitgen fit`` says after a fit: per equation its terms, AIC and training errors, what it
    assumed, a warning when it assumed no noise, and the held-out figures (``held_out``: poses asked)."""
    lines, crit = [], criterion(model.fit_info)
    for e in model.equations:
        i = model.fit_info["outputs"][e.name]
        err = i["model_training_error"]
        aic = f"{i['aic']:.2f}" if abs(i["aic"]) < 1e9 else f"{i['aic']:.4g}"  # a --k of 1e300 gives 1e300s
        lines.append(f"{e.name}: {len(e.terms)} terms, {crit} {aic}, training max error {err['max']:.4g} "
                     f"{e.unit}, RMS {err['rms']:.4g}, condition {i['condition']:.3g}")
    lines.append(fit_assumptions(model.fit_info, model.input_units))
    noise = model.fit_info["noise"]
    if noise["device"] is None and noise["data"] == 0:
        lines.append("warning: the dataset was simulated without noise and names no sensor this fitgen knows: fitted "
                     "without the device's noise (give --sensor FILE or --noise X)")
    elif noise["device"] == 0 and str(noise.get("device_source", "")).startswith("sensor "):
        # a file that leaves its noise out reads 0; --noise 0 (the paper's procedure) says so on purpose
        lines.append(f"warning: {noise['device_source']} gives no noise figure (noise missing or 0 in its transfer's "
                     "table): fitted without the device's noise, so the equations may amplify it and the held-out "
                     "figures are noise-free (add the noise to the file, or give --noise X; --noise 0 to mean it)")
    text = "\n".join(lines) + "\n"
    if "held_out" in model.fit_info:
        return text + deployed_table(model)
    if held_out:
        text += "no held-out figures: the dataset names no sensor to simulate held-out poses with (give --sensor)\n"
    return text


def deployed_table(model: Model) -> str:
    """Markdown: held-out errors per precision (the model file's ``held_out`` record), '' without one;
    InputError for a record that is not fitgen's."""
    rec = model.fit_info.get("held_out")
    if not isinstance(rec, dict):
        return ""
    try:
        return _deployed_table(model, rec)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise InputError(f"the model file's held_out record is malformed ({type(exc).__name__}: {exc}); fit it "
                         "again with fitgen fit") from None


def _deployed_table(model: Model, rec: dict) -> str:
    post = rec.get("posterior")
    unit_file = None if rec.get("drawing") else rec.get("sensor_file")  # a drawing's own file is recorded too
    on = (f"on {post['units']} units drawn from the posterior of the identified unit ({rec.get('sensor', '?')}) "
          "(the median of each figure, their range in brackets: the unit is one draw of it)"
          if isinstance(post, dict) else
          f"on unit {rec.get('sensor', '?')} ({unit_file})" if unit_file else
          f"on the drawing {rec.get('sensor', '?')}: a built unit differs from it (fitgen identify)")
    lines = [f"### deployed accuracy, held out ({rec['poses']} random poses in the training box, seed {rec['seed']}; "
             f"noise {rec['noise']:g} {model.input_units} rms, {rec['noise_draws']} draws), {on}", "",
             "| output | unit | precision | max | RMS | max, noise | RMS, noise | rounding's share |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for e in model.equations:
        for prec, errs in rec["errors"].items():
            if "unavailable" in errs:
                continue
            x = errs[e.name]
            cells = [_g(x[f]) + (f" ({_g(x[f + '_lo'])}-{_g(x[f + '_hi'])})" if f + "_lo" in x else "")
                     for f in ("max", "rms", "noisy_max", "noisy_rms")]
            lines.append(f"| {e.name} | {e.unit} | {prec} | {' | '.join(cells)} | {x['share']:.1%} |")
    missing = [f"{p}: {errs['unavailable']}" for p, errs in rec["errors"].items() if "unavailable" in errs]
    lines += [""] + [f"Not available in {m}" for m in missing] + ([""] if missing else [])
    return "\n".join(lines + uncalibrated_lines(model, rec)) + "\n"


def uncalibrated_lines(model: Model, rec: dict) -> list[str]:
    """Markdown lines: what the drawing's model does flashed uncalibrated into built units (the ``uncalibrated``
    record of its ``held_out`` record ``rec``), none without one."""
    unc = rec.get("uncalibrated")
    if not isinstance(unc, dict):
        return []
    errs = unc["errors"]
    cells = [f"{e.name} {_g(errs[e.name]['noisy_max'])} {e.unit} ({_g(errs[e.name]['noisy_max_lo'])}"
             f"-{_g(errs[e.name]['noisy_max_hi'])})" for e in model.equations if e.name in errs]
    return [f"A built unit is not its drawing: flashed uncalibrated into {unc['units']} units drawn within the "
            f"drawing's [tolerances] (seed {unc['seed']}, {unc['precision']}), this model's max error with noise is "
            + ", ".join(cells) + " (the median over the units, their range in brackets). Calibrate each unit: "
            "fitgen schedule, tactile-host capture --stage, fitgen identify, then fit its twin "
            "(docs/calibration.md).", ""]


def format_report(model: Model, ds: Dataset | None = None, title: str = "", paper: bool = False) -> str:
    """Markdown: terms and fit figures per output; errors on ``ds`` (default: the fit's training errors)."""
    info = model.fit_info.get("outputs", {})
    parts = [f"## {title}" if title else "## Model", ""]
    n = len(model.equations)
    parts.append(f"Model {model.sha256[:12]}: {n} output{'s' * (n != 1)}, {model.n_inputs} inputs "
                 f"({model.input_units}); fitted on {model.fit_info.get('dataset_rows', '?')} rows, "
                 f"d-terms: {model.fit_info.get('d_terms', '?')}.")
    parts.append("")
    crit = criterion(model.fit_info)
    cap = (model.fit_info.get("settings") or {}).get("max_terms")
    head = ["output", "terms", crit, "steps", "cond"]
    rows = []
    for e in model.equations:
        i = info.get(e.name, {})
        rows.append([e.name, str(len(e.terms)), _g(i["aic"]) if "aic" in i else "-",
                     str(len(i.get("steps", [])) - 1) if "steps" in i else "-",
                     _g(i["condition"]) if "condition" in i else "-"])
    parts += [_table(head, rows), ""]
    parts += [fit_assumptions(model.fit_info, model.input_units), ""]
    deployed = deployed_table(model)
    if deployed:
        parts.append(deployed)

    if ds is not None:
        ev = errors_on(model, ds)
        label = f"errors on {ds.n_rows} rows (the model in double; fitgen predict --precision gives the device's)"
        head = ["output", "unit", "max", "RMS", "p95"] + (["paper sim max"] if paper else [])
        rows = []
        for e in model.equations:
            if e.name not in ev:
                continue
            s = ev[e.name]["all"]
            rows.append([e.name, e.unit, _g(s["max"]), _g(s["rms"]), _g(s["p95"])]
                        + ([str(PAPER_SIM_MAX_ERROR.get(e.name, "-"))] if paper else []))
        parts += [f"### {label}", "", _table(head, rows), ""]
        by = {n: r["by_dz"] for n, r in ev.items() if "by_dz" in r}
        if by:
            levels = sorted(next(iter(by.values())))
            head = ["output"] + [f"max at dz={lv:g}" for lv in levels]
            rows = [[n] + [_g(by[n][lv]["max"]) for lv in levels] for n in by]
            parts += ["### max error per dz level", "", _table(head, rows), ""]
    parts.append("### terms")
    parts.append("")
    for e in model.equations:
        # every digit: an equation with cancelling terms cannot be evaluated from rounded coefficients
        parts.append(f"- {e.name} = {e.intercept!r} " + " ".join(
            f"{'-' if c < 0 else '+'} {abs(c)!r} {t.text}" for t, c in zip(e.terms, e.coefficients)))
    parts.append("")
    parts.append(f"### {crit} trace")
    parts.append("")
    parts.append(f"Bidirectional stepwise from eq. 1 on {crit}"
                 + (f", at most {cap} terms per output (--max-terms): eq. 1 cut down to the cap first, and at the "
                    "cap a term exchanged for a better one (- a + b)" if isinstance(cap, int) else "") + ".")
    parts.append("")
    for e in model.equations:
        steps = info.get(e.name, {}).get("steps")
        if steps:
            moves = ", ".join(f"{m} ({a:.1f})" for m, a in steps[1:]) or "no move"
            cut = info.get(e.name, {}).get("initial_over_cap") or []
            parts.append(f"- {e.name}: start {steps[0][1]:.1f}" + (f" (eq. 1 without {', '.join(cut)})" if cut else "")
                         + f"; {moves}")
    return "\n".join(parts) + "\n"


def sweep_sensor(sensor, model, given: str):
    """``sensor`` (``given`` so) in the transfer that gives ``model``'s units; InputError when the model was fitted
    on another."""
    from fitgen.fitting.holdout import fitted_sensor

    return fitted_sensor(sensor, model, "its sweep on this one would not be the model's", given=given)


REFINE_WORSE = 1.05  # a refined training RMS past this many times the equations' own
BLIND_SHARE = 0.5  # a training RMS past this share of an output's own spread, where a cause is found
NEAR_CONSTANT = 0.8  # past this share the equation is near a constant, cause found or not


def posterior_note(spec) -> list[str]:
    """A unit file whose posterior is not beside it (copied alone): fit would refuse the twin's rows, so simulate
    says so before the user fits."""
    if spec is None or not Path(spec).is_file():
        return []
    from fitgen.fitting.unitrecord import load_posterior

    try:
        load_posterior(spec)
    except InputError as exc:
        return [f"{exc}; fitgen fit refuses these rows until then"]
    return []


def simulate_notes(sensor, poses, labels: str, spec: str, adc_bits: int | None = None,
                   source: dict | None = None, replaced=None) -> list[str]:
    """What `fitgen simulate` says of its rows beyond their count: rows where an element's reading no longer
    follows the pose (``spec``: the --sensor given, for the command that tells more; ``adc_bits``: --adc-bits,
    which gives a raw transfer a converter and so a full scale its readings clip at); of a scene's grid
    (``source``: the poses' provenance), levels raised and a box past the sensor's travel; ``replaced``: the unit
    file ``--unit`` wrote over one of another unit."""
    from fitgen.physics.pose import off_skin
    from fitgen.physics.simulate import rows_past_linear, with_adc_bits

    if adc_bits is not None and sensor.transfer == "raw":
        sensor = with_adc_bits(sensor, adc_bits)
    notes = _scene_notes(sensor, source or {})
    if replaced is not None:  # as identify says it: a model held out on the file no longer matches it
        notes.append(f"{replaced} held another unit, now replaced: rows and models made with that unit no longer "
                     "match it (fit and check refuse them)")
    if lifted := int(off_skin(poses).sum()):  # a schedule's rest rows; in a grid or a box, labels that read as rest
        notes.append(f"{lifted} of {len(poses)} rows lie above first contact (dz > 0.05 mm): the indenter is off the "
                     "skin there, and they read the sensor at rest (fitgen fit leaves them out)")
    if clipped := int(rows_past_linear(sensor, poses, labels).sum()):
        notes.append(f"{clipped} of {len(poses)} rows ({clipped / len(poses):.0%}) have an element past its linear "
                     "range (saturated, or on the ADC's rails), whose reading there no longer follows the pose; "
                     f"`fitgen observe --sensor {spec} --transfer {sensor.transfer}` tells whether the others still "
                     "resolve it")
    return notes


def _scene_notes(sensor, source: dict) -> list[str]:
    """A scene grid's levels raised for the fit, and a scene box that reaches past the sensor's ``[travel]``."""
    from fitgen.physics.scenes import load_scene

    if "scene_spec" not in source:
        return []
    scene, notes = load_scene(source["scene_spec"]), []
    if source.get("scene_grid_levels", scene.levels) != scene.levels:
        notes.append(f"scene {scene.name}: its grid takes {source['scene_grid_levels']} levels per moving component, "
                     f"not its {scene.levels}, for the rows the fit's first equation needs")
    return notes + travel_notes(sensor, f"scene {scene.name}", scene.ranges)


def travel_notes(sensor, what: str, ranges: dict) -> list[str]:
    """A note when the pose box ``ranges`` of ``what`` reaches past the sensor's ``[travel]``, else none."""
    past = [f"{a} {lo:g}..{hi:g} mm (travel {t[0]:g}..{t[1]:g})" for a, t in sensor.travel.items()
            for lo, hi in [ranges[a]] if lo < t[0] or hi > t[1]]
    if not past:
        return []
    return [f"{what}: its box reaches past the sensor's travel ([travel] of its file): {', '.join(past)}; the skin "
            "does not carry the magnet that far, and poses there describe no contact the sensor will see"]


def _blind_causes(model: Model, ds, sensor) -> list[str]:
    """What keeps the readings from carrying an output, of what can be checked here: fewer elements than outputs,
    rows with an element past its linear range (where ``sensor``, the rows' own, is known)."""
    causes = []
    if ds.n_inputs < len(model.equations):
        causes.append(f"{ds.n_inputs} elements for {len(model.equations)} outputs")
    if sensor is not None:
        from fitgen.physics.simulate import rows_past_linear

        past = float(rows_past_linear(sensor, ds.poses(), ds.meta.get("labels", "stage")).mean())
        if past >= 0.05:
            causes.append(f"an element past its linear range in {past:.0%} of the rows")
    return causes


def fit_notes(model: Model, ds, data, units, sensor=None) -> list[str]:
    """What a user should know of a fit to dataset ``ds`` (``sensor``: its rows' own, where known) beyond its
    summary: units assumed, repeated rows, powers withheld, equations near the rows, outputs barely carried, why."""
    rows = len(ds.inputs)
    notes = [] if units else [f"{data} has no meta saying its readings' units: taken as mT (give --units V for "
                              "volts, as an ADC gives them)"]
    if ds.n_inputs > MAX_INPUTS:  # said now, not after the fit when codegen refuses it
        notes.append(f"{ds.n_inputs} inputs: the generated C's status holds one bit per input, at most {MAX_INPUTS}, "
                     "so codegen, verify and flash refuse this model; Model.predict and fitgen predict take it")
    copies = {j: i for j in range(ds.n_inputs) for i in reversed(range(j))
              if np.array_equal(ds.inputs[:, i], ds.inputs[:, j])}
    simulated = bool(ds.meta.get("generator")) and "samples_per_row" not in ds.meta
    if copies and not (simulated and "scene_spec" in ds.meta):  # a scene's box is the poses the device will see
        # its terms and the original's are one column to the fit: both stay in, weighed against each other
        said = ", ".join(f"v{j + 1} reads what v{i + 1} reads" for j, i in copies.items())
        notes.append(f"{said} on every row: " + (
            "the simulated poses keep the magnet where these elements read alike (the ring's symmetry: a scene that "
            "holds dx and dy at 0, say), so the fit cannot tell them apart; a device's poses off that line read "
            "them apart, where the estimates were not fitted" if simulated else
            "one ADC channel read twice (a channel map that lists it twice) or two elements wired together; the "
            "fit learns nothing from the copy, and on a device that reads them apart the estimates will be off by "
            "however much they differ"))
    # a row counted twice weighs twice and adds to n in AIC: terms are admitted on less evidence
    if repeats := len(ds.repeats()):
        notes.append(f"{repeats} of {rows} rows repeat another row exactly: the fit counts each as a measurement of "
                     "its own, so AIC admits terms on less evidence than the data hold; drop the repeats, or average "
                     "repeated readings of one pose into one row")
    needing = [e for e in (model.fit_info.get("settings") or {}).get("exponents") or [] if "-" in e or "/" in e]
    if needing and len(low := np.flatnonzero(~(ds.inputs.min(axis=0) > 0))):  # the terms rule withheld them
        k, r, one = int(low[0]), int(np.argmin(ds.inputs[:, low[0]])), len(low) == 1
        notes.append(f"{', '.join(f'v{j + 1}' for j in low)} read{'s' if one else ''} 0 or less on some rows "
                     f"(v{k + 1}: {ds.inputs[r, k]:g} on data row {r + 1}): the fit was not offered "
                     f"{'its' if one else 'their'} powers {', '.join(needing)}, which need readings > 0, and may be "
                     "the poorer for it; a glitch row? leave it out; every reading below 0? correct the readings")
    no_d = _d_terms_note(model)
    notes += no_d
    causes, noise = None, (model.fit_info.get("noise") or {}).get("device") or 0.0  # single samples
    for e in model.equations:
        rms, sd = model.fit_info["outputs"][e.name]["model_training_error"]["rms"], float(ds.target(e.name).std())
        if not (sd > 0 and rms > BLIND_SHARE * sd):
            continue
        causes = _blind_causes(model, ds, sensor) if causes is None else causes
        said = f"{e.name}'s {'refined estimate' if model.refine else 'equation'} leaves {rms / sd:.0%} of its " \
               f"spread over the rows (training RMS {rms:.3g} of {sd:.3g} {e.unit})"
        if causes:
            notes.append(f"{said}: the readings barely carry {e.name} here ({'; '.join(causes)}); `fitgen observe` "
                         "tells how well each output can be seen")
        elif not e.terms and isinstance(k := (model.fit_info.get("settings") or {}).get("k"), (int, float)) and k > 2:
            notes.append(f"{said}: it has no terms, as the penalty per term (k = {k:.3g}) admitted none; a smaller "
                         "--k (aic: 2) may admit some")
        elif rms > NEAR_CONSTANT * sd and no_d and e.name in ("thx", "thy"):
            notes.append(f"{said}: it is close to a constant, fitted without the displacement terms (above)")
        elif rms > NEAR_CONSTANT * sd and isinstance(cap := (model.fit_info.get("settings") or {}).get("max_terms"),
                                                     int) and len(e.terms) >= cap:
            notes.append(f"{said}: it is close to a constant within --max-terms {cap}, which may be too few terms for "
                         f"{e.name} on these readings: a larger cap (or none) tells")
        elif rms > NEAR_CONSTANT * sd and isinstance(cap, int):  # the cap did not bind: the search stopped short of it
            notes.append(f"{said}: it is close to a constant with {len(e.terms)} of the {cap} terms --max-terms "
                         "allows: the search stopped where no one step improves it, which another cap (its start is "
                         "eq. 1 cut down to the cap) or none may pass")
        elif rms > NEAR_CONSTANT * sd:  # no cause found; the paper's tilts, fitted its way, leave about half
            notes.append(f"{said}: it is close to a constant"
                         + (f"; against the {noise:.3g} {model.input_units} rms of reading noise it is fitted for, "
                            f"the readings barely carry {e.name} here" if noise > 0 else "")
                         + "; `fitgen observe` tells how well each output can be seen")
    for e in model.equations:  # a refinement whose forward model misses these readings pulls the estimate away
        fi = model.fit_info["outputs"][e.name]
        refined, alone = fi["model_training_error"]["rms"], (fi.get("equations_training_error") or {}).get("rms")
        if alone is not None and refined > REFINE_WORSE * alone:
            notes.append(f"the refinement leaves {e.name} worse than its equations alone on the rows (training RMS "
                         f"{refined:.3g} against {alone:.3g} {e.unit}): its forward model does not describe these "
                         "readings well enough (more --refine-terms, or data that vary in every pose component, "
                         "docs/refine.md); fit without --refine")
    crowded = [e for e in model.equations if len(e.terms) + 1 > rows / 3 and not _holds_out_as_trained(model, e.name)]
    if crowded:  # AIC's penalty is no guard when the terms near the rows: the equation threads the rows' noise
        e = max(crowded, key=lambda e: len(e.terms))
        notes.append(f"{e.name} has {len(e.terms)} terms on {rows} rows: it threads these rows (and their noise, "
                     "where they have some) more than it follows the sensor, and errs between them; more rows, "
                     "--max-terms, or fit the identified unit's simulated rows (fitgen identify)")
    return notes


def _holds_out_as_trained(model: Model, name: str) -> bool:
    """Whether output ``name``'s noise-free held-out RMS (in the precision fitted for) is within twice its training
    RMS: an equation that threaded its rows would err between them."""
    info = model.fit_info
    held = ((info.get("held_out") or {}).get("errors") or {})
    errors = held.get((info.get("precision") or {}).get("target")) or held.get("double") or {}
    rms = (errors.get(name) or {}).get("rms")
    trained = info["outputs"][name]["model_training_error"]["rms"]
    return isinstance(rms, float) and rms <= 2 * trained


def _d_terms_note(model: Model) -> list[str]:
    """A tilt fitted without the displacement terms eq. 1 gives it (d from dx, dy and dz's own equations), because
    the fit did not take all three: why its equation may leave more than with them."""
    from fitgen.equations.terms import DISPLACEMENTS, ROTATIONS

    names = model.output_names
    tilts, missing = [o for o in names if o in ROTATIONS], [o for o in DISPLACEMENTS if o not in names]
    settings = model.fit_info.get("settings") if isinstance(model.fit_info, dict) else None
    if not tilts or not missing or not (isinstance(settings, dict) and settings.get("d_terms")):
        return []
    return [f"{' and '.join(tilts)} fitted without the displacement terms eq. 1 gives a tilt (they take dx, dy and "
            f"dz from their own equations, and the fit has no {', '.join(missing)}): fit --outputs "
            f"{','.join([*DISPLACEMENTS, *tilts])} to have them"]


ROUNDING_NOTE = 0.25  # of the noise the model was fitted for: an ADC's rounding past it is worth a word


def rounding_note(model: Model, lsb: float) -> str | None:
    """What codegen says of codes of ``lsb`` (a --input-lsb) whose rounding, lsb / sqrt(12), is large beside the
    reading noise the model was fitted for, and coarser than the ADC the fit took (whose rounding it counts)."""
    from fitgen.equations.inputscale import fitted_input_scale

    noise = (model.fit_info.get("noise") or {}).get("device") if isinstance(model.fit_info, dict) else None
    if not isinstance(noise, (int, float)) or not noise > 0 or not lsb / np.sqrt(12) > ROUNDING_NOTE * noise:
        return None
    fitted = fitted_input_scale(model)
    if fitted is not None and lsb <= fitted[0] * 1.001:  # an LSB typed to a few digits is the same ADC
        return None
    q, units = lsb / np.sqrt(12), model.input_units
    return (f"codes of {lsb:.3g} {units} round each reading by {q:.3g} {units} rms, {q / noise:.0%} of the "
            f"{noise:.3g} {units} rms of reading noise the model was fitted for: neither the fit nor the model "
            "file's figures count it; simulate the rows with this ADC (adc_bits, adc_min, adc_max in the sensor "
            "file's [transfer.gmr]) and fit again to have it counted")


LABEL_MARGIN = 0.1  # of the box's width: a label past it lies clearly outside the box


def data_notes(model: Model, ds: Dataset) -> list[str]:
    """What `fitgen report --data` says of the rows beside its errors: :func:`predict_notes` of the double model's
    estimates (rows clamped, rows estimated far outside the fitted box: readings of another sensor)."""
    with np.errstate(over="ignore", invalid="ignore"):
        pred, status = model.predict(ds.inputs, with_status=True)
    return predict_notes(model, pred, status, "double", {n: ds.target(n) for n in ds.target_names})


def predict_notes(model: Model, pred: np.ndarray, status: np.ndarray, precision: str,
                  labels: dict | None = None) -> list[str]:
    """What `fitgen predict` says of its rows beyond the estimates: rows clamped into the domain, rows with no
    estimate, and rows whose estimate lies outside the pose box the model was fitted in (its held-out record's)
    by more than the box's width: readings of another sensor, as the drawing's model reads a built unit's, unless
    the rows' ``labels`` (pose columns by name) lie clearly outside the box too (past a tenth of its width beyond
    it: a calibration capture's travel; one just past its edge still reads as the estimate's fault)."""
    clamped, refused = int(np.sum(status > 0)), int(np.sum(status < 0))
    notes = ([f"{clamped} row{'s' * (clamped != 1)} clamped into the domain"] if clamped else []) + (
        [f"{refused} row{'s' * (refused != 1)} with no estimate (status -1: a reading not finite in "
         f"{precision})"] if refused else [])
    box = model.held_out_box
    if box and len(pred):
        far = model.far_outside(pred) & (status >= 0)
        if n := int(far.sum()):
            where = ", ".join(f"{o} {lo:g}..{hi:g}" for o, (lo, hi) in box.items())
            beyond = np.zeros(len(pred), dtype=bool)  # rows labelled outside the box: estimates that extrapolate
            for o, (lo, hi) in box.items():
                if o in (labels or {}):
                    margin = LABEL_MARGIN * (hi - lo)
                    beyond |= (labels[o] < lo - margin) | (labels[o] > hi + margin)
            m = int((far & beyond).sum())
            notes.append(f"{n} row{'s' * (n != 1)} estimated outside the pose box the model was fitted in ({where}) by "
                         "more than its width" + (
                             ", all labelled outside it too: poses the model makes no claim for" if m == n else
                             f" ({m} labelled outside it too, where it makes no claim; the others:" if m else ":")
                         + ("" if m == n else " readings of another sensor than the model's? a built unit needs its "
                            "own calibration (docs/calibration.md)" + (")" if m else "")))
    return notes

