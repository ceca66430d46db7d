"""The ``fitgen check`` command: a calibrated model on a check capture of its unit, its measured errors beside the
ones the unit's identification predicts; a thin layer over fitgen.fitting.check."""

from __future__ import annotations

import sys

from fitgen.app.captureinput import at_t0, not_levels
from fitgen.base.errors import InputError
from fitgen.base.fileio import write_all


def _check_temperature(ds, sensor, temp_comp: str | None, capture: str):
    """A check capture and a line on its temperature against the unit's (the unit file's ``capture_degc``): with
    ``temp_comp``, its rows taken from their own temperatures to the compensation's t0, which must be the unit's;
    without, a note when it was read more than CAPTURE_DEGC_TOL from the unit's, which the prediction does not
    draw; '' when there is nothing to say."""
    import numpy as np

    from fitgen.fitting.holdout import rest_spread
    from fitgen.fitting.unitrecord import capture_temperature
    from fitgen.physics.transfer import readings
    from host.tempunit import rest_note
    from host.temperature import CAPTURE_DEGC_TOL, load_tempcomp, unit_capture_degc

    theirs = unit_capture_degc(sensor.source)
    mine = capture_temperature(ds.meta, ds.n_rows).get("capture_degc")  # as identify takes a capture's
    if temp_comp:
        tc = load_tempcomp(temp_comp)  # a file that is none (a folder, a model) said as such, before what the unit lacks
        if theirs is None:
            raise InputError(f"--temp-comp {temp_comp}: the unit file ({sensor.name}) records no temperature it was "
                             "identified at (capture_degc: its capture had no thermistor), so there is none to take "
                             "the check's rows to")
        ds, info = at_t0(ds, tc, temp_comp, capture, "check")
        # against the unit's rest: a check's schedule has no row at rest
        rest = readings(sensor, np.zeros((1, 5)), adc_bits=0)[0]
        if note := rest_note(tc, rest, rest_spread(sensor), f"--temp-comp {temp_comp}", f"the unit ({sensor.name})"):
            print(f"check: {note}", file=sys.stderr)
        t0 = info["capture_degc"]
        if abs(t0 - theirs) > CAPTURE_DEGC_TOL:
            raise InputError(f"--temp-comp {temp_comp} takes the check's rows to {t0:g} degC, but the unit was "
                             f"identified at {theirs:.1f} degC (capture_degc): identify it with --temp-comp {temp_comp} "
                             "too, or give a compensation about its temperature")
        return ds, (f"check: the rows taken from {info['compensated_from_degc']:.2f} degC (their median) to {t0:g} "
                    "degC, the unit's, by the compensation")
    if mine is not None and theirs is not None and abs(mine - theirs) > CAPTURE_DEGC_TOL:
        return ds, (f"check: note: the check capture was read at {mine:.1f} degC and the unit identified at "
                    f"{theirs:.1f} degC; its elements' offsets and gains drift with temperature, which the prediction "
                    "does not draw: --temp-comp TC.json takes the check's rows to the unit's temperature")
    return ds, ""


FEW_CHECK_ROWS = 10  # a check capture of fewer rows in contact gets a word: its max errors are a handful's


def cmd_check(args) -> int:
    """``check``: the measured errors on a check capture beside the ones the unit's identification predicts."""
    from fitgen.app import plots
    from fitgen.c.codegen import check_magnitudes
    from fitgen.equations.model import check_input_units, load_model
    from fitgen.fitting.check import DRAWS, NO_BOX, TOO_FAR, box_words, check_capture
    from fitgen.fitting.holdout import fitted_sensor, fitted_sensor_spec
    from fitgen.physics.dataset import load_capture
    from fitgen.physics.sensor import load_sensor

    folder = plots.require(args.plot) if args.plot else None
    model = load_model(args.model)
    check_magnitudes(model, "double")  # as predict: a model whose terms overflow checked 'as predicted' on inf
    not_levels(args.capture)
    ds = load_capture(args.capture)
    check_input_units(model, ds.meta.get("units"), f"{args.capture}'s readings", f"model {args.model}")
    if not set(ds.target_names) & {"dx", "dy", "dz"}:
        raise InputError(f"{args.capture} has no stage displacement (dx, dy, dz): a check needs each row's pose")
    if not model.pose_box:
        # a direct fit on rows a simulation read: that sensor's file, not identify's (a twin's is identify's)
        read_from = model.fit_info.get("sensor_sha256")
        which = (f"the file of sensor {str(read_from)[:12]}, whose readings it was fitted on (a simulation's: the "
                 "--sensor that simulate or capture --simulate read)" if read_from else "the unit's file (identify's)")
        raise InputError(f"model {args.model}: {NO_BOX}: fit it again with --sensor {which}, or check the twin's "
                         "model (identify, simulate --sensor unit.toml, fit)")
    spec = args.sensor or fitted_sensor_spec(model)
    if spec is None:
        raise InputError(f"model {args.model}: the sensor its held-out figures were made on is not found here (or "
                         "has changed): give the unit's file (fitgen identify writes it) as --sensor, or check the "
                         "twin's model (identify, simulate --sensor unit.toml, fit)")
    sensor = fitted_sensor(load_sensor(spec), model, "give the unit file it was fitted on", given=spec)
    sha = ds.sha256  # the capture's as written, before a compensation
    ds, heat = _check_temperature(ds, sensor, args.temp_comp, args.capture)
    if heat:
        print(heat, file=sys.stderr)
    result, source = check_capture(model, ds, sensor, spec, rig_error=args.rig_error, zero_error=args.zero_error,
                                   precision=args.precision, capture=args.capture, sha256=sha)
    print(f"check: zero error {result.zero_error:.3g} mm: {result.zero_said}", file=sys.stderr)
    if result.outside:
        print(f"check: {result.outside} rows of {args.capture} lie outside the pose box the model was fitted in "
              f"({box_words(model.pose_box)}), where it makes no claim, or within {result.margin:.2g} mm of its "
              "edge, where the stage's error may carry them out: left out", file=sys.stderr)
    where = (f"{result.units} units drawn from the posterior of {sensor.name} ({spec})" if result.identified
             else f"{sensor.name} (no posterior: its noise and the stage's error alone)")
    print(f"check: {result.rows} rows of {args.capture} in contact, estimated in {result.precision}; predicted on "
          f"{where}, {DRAWS} draws each of the stage's error ({result.rig_error:g} mm, {result.rig_said})"
          + (f", the zero's ({result.zero_error:.3g} mm)" if result.zero_error else "")
          + f" and the rows' noise ({source})")
    if result.rig_error or result.zero_error:  # else a user reads the check's figures against the model file's
        print("check: the stage's labels err too: the measured and the predicted figures both carry it, so they run "
              "above the model file's held-out figures (the model's error alone, at exact poses)", file=sys.stderr)
    if result.rows < FEW_CHECK_ROWS:  # each max is then the max of a handful: a verdict on little
        print(f"check: note: {result.rows} rows say little of a unit's errors over its box; fitgen schedule --check 30 "
              "gives a check capture", file=sys.stderr)
    print()
    print("| output | unit | max error | predicted max: median (least-greatest) | RMS error | predicted RMS | |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for o in result.outputs:
        unit = model.equation(o).unit
        (mm, ml, mh), (rm, rl, rh) = result.predicted(o, "max"), result.predicted(o, "rms")
        figure, beyond = result.worst(o)
        said = "as predicted" if beyond <= 1 else f"{'max' if figure == 'max' else 'RMS'} {beyond:.2g}x the greatest"
        print(f"| {o} | {unit} | {result.measured[o]['max']:.3g} | {mm:.3g} ({ml:.3g}-{mh:.3g}) | "
              f"{result.measured[o]['rms']:.3g} | {rm:.3g} ({rl:.3g}-{rh:.3g}) | {said} |")
    if folder is not None:
        [png] = write_all([(folder / "check.png",
                            plots.check_png(result, {o: model.equation(o).unit for o in result.outputs}))])
        print(f"plot: {png}", file=sys.stderr)
    failed = result.failed()
    if failed:
        warmer = heat.startswith("check: note:")  # read away from the unit's temperature, not compensated
        drawn = f"it was fitted on the drawing {sensor.name}, which a built unit is not: fit the twin's model " \
            "(identify, simulate --sensor unit.toml, fit); " if sensor.is_drawing and not result.identified else ""
        print(f"\ncheck: {', '.join(failed)} err beyond {TOO_FAR:g}x every prediction (max or RMS): the model does not "
              f"describe this unit as it is now ({drawn}a knock, the sensor moved on its bed, another unit's file, the "
              "temperature); "
              + ("check again with --temp-comp (the note above) before you " if warmer else "")
              + "capture, identify and fit again", file=sys.stderr)
        return 1
    print(f"\ncheck: every output within what {'the identification' if result.identified else 'sensor ' + sensor.name} "
          "predicts", file=sys.stderr)
    return 0
