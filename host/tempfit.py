"""The temperature compensation from captures each taken at one temperature (``tactile-host tempcomp-fit``): what
``capture --temperature`` fits from its levels, for captures it cannot take, such as a stage's (`capture --stage`
at each temperature, a thermistor on the bus)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fitgen.base.errors import InputError
from fitgen.physics.dataset import load_dataset, row_degc, thermistor_degc

from host.temperature import TempComp, fit_tempcomp_at, spread_note


def _temperatures(ds, path) -> np.ndarray:
    """Each row's temperature: as the thermistor read it around the row (``row_degc``), else as the capture started
    (``thermistor_degc``), else as `capture --temperature` set the level (``temperature_set``, no thermistor)."""
    each = row_degc(ds.meta, ds.n_rows)
    if each is not None:
        return np.asarray(each, dtype=float)
    # a record there but damaged: the fallback would fit rows that warmed as if at one temperature, in silence
    for key, what in (("row_degc", f"one finite temperature for each of its {ds.n_rows} rows"),
                      ("thermistor_degc", "a temperature")):
        if key in ds.meta and (key == "row_degc" or thermistor_degc(ds.meta) is None):
            raise InputError(f"{path}'s meta has a {key} that is not {what}: the thermistor read no temperature "
                             "around some row (its divider open or shorted), or the meta was edited or cut short; "
                             "the rows' temperatures are not known: take the capture again")
    degc = thermistor_degc(ds.meta)
    if degc is None and isinstance(ds.meta.get("temperature_set"), (int, float)):
        degc = float(ds.meta["temperature_set"])
    if degc is None or not np.isfinite(degc):
        raise InputError(f"{path} records no temperature (its capture read no thermistor: temp=CHIP@ADDRESS:INPUT in "
                         "--adc): a compensation needs each capture's temperature")
    return np.full(ds.n_rows, float(degc))


def _pose_set(ds) -> set:
    return {tuple(p) for p in np.round(ds.poses(), 6).tolist()}


def captures_tempcomp(paths, t0: float | None = None) -> tuple[TempComp, list[str]]:
    """The per-element compensation (host.temperature.fit_tempcomp) from the captures at ``paths``, of one sensor
    through one channel map, each holding the same poses at its own temperatures (its rows' as its meta records
    them), and notes on it. ``t0``: one of their temperatures (default: as fit_tempcomp chooses). InputError for
    captures that do not go together."""
    if len(paths) < 2:
        raise InputError("give two or more captures, each taken at its own temperature")
    sets = [load_dataset(p, min_rows=1) for p in paths]
    first, name = sets[0], paths[0]
    for ds, path in zip(sets, paths):
        if not ds.meta:
            raise InputError(f"{path} has no meta ({Path(str(path)).name}.meta.json), which says at what temperature "
                             "and through which channel map its rows were read: restore it, or take the capture again")
    for key, what in (("adc", "channel map (--adc)"), ("sensor_sha256", "simulated sensor")):
        # against the first capture that records one, in any order: the first given had been the only reference
        ref = next(((ds.meta[key], p) for ds, p in zip(sets, paths) if key in ds.meta), None)
        for ds, path in zip(sets, paths):
            if ref is not None and ds.meta.get(key) != ref[0]:
                raise InputError((f"{path} was captured through another {what} than {ref[1]}" if key in ds.meta else
                                  f"{path}'s meta records no {what}, which {ref[1]}'s does") +
                                 ": one compensation is for one sensor read one way")
    seen = {first.sha256: name}
    for ds, path in zip(sets[1:], paths[1:]):
        if ds.sha256 in seen:  # its rows would count twice, and pull t0 to its temperature
            raise InputError(f"{path} holds the same rows as {seen[ds.sha256]}: give each capture once")
        seen[ds.sha256] = path
        if ds.n_inputs != first.n_inputs or ds.target_names != first.target_names:
            raise InputError(f"{path} has other columns than {name}: capture each temperature with one schedule")
        # a pose at one temperature only tells nothing of its drift, and pulls the others' fit (a capture stopped
        # early, another schedule): each capture holds every pose
        if _pose_set(ds) != _pose_set(first):
            raise InputError(f"{path} holds other poses than {name}: capture each temperature with one schedule, "
                             "to its end (a capture stopped early resumes with the same command)")
    temps = [_temperatures(ds, p) for ds, p in zip(sets, paths)]
    medians = [float(np.median(t)) for t in temps]
    if len({round(t, 1) for t in medians}) < 2:
        raise InputError(f"the captures were all read at {medians[0]:.1f} degC: give captures at two or more "
                         "temperatures")
    tc = fit_tempcomp_at(np.vstack([ds.inputs for ds in sets]), np.vstack([ds.poses() for ds in sets]),
                         np.concatenate(temps), t0=t0, source="the captures")
    tc.info["captures"] = [str(p) for p in paths]
    if isinstance(first.meta.get("adc"), str):  # the elements each coefficient is for: read and pi-build compare
        tc.info["adc"] = first.meta["adc"]  # every capture's, by the check above
    notes = [] if tc.info["gain_fitted"] else ["one pose per capture gives offsets only (gain needs two poses)"]
    spread = spread_note(tc)
    return tc, notes + ([spread.removeprefix("note: ")] if spread else [])
