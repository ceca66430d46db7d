"""The temperature compensation from captures each taken at one temperature (``tactile-host tempcomp-fit``): what
``capture --temperature`` fits from its levels, for captures it cannot take, such as a stage's (`capture --stage`
at each temperature, a thermistor on the bus)."""

from __future__ import annotations

import numpy as np

from fitgen.base.errors import InputError
from fitgen.physics.dataset import load_dataset, row_degc, thermistor_degc
from fitgen.physics.pose import contact_poses

from host.temperature import TempComp, fit_tempcomp


def _temperature(ds, path) -> float:
    """The temperature ``path``'s rows were read at: its thermistor as the capture started, else its rows' median."""
    degc = thermistor_degc(ds.meta)
    if degc is None and (each := row_degc(ds.meta, ds.n_rows)) is not None:
        degc = float(np.median(each))
    if degc is None:
        raise InputError(f"{path} records no temperature (its capture read no thermistor: temp=CHIP@ADDRESS:INPUT in "
                         "--adc): a compensation needs each capture's")
    return float(degc)


def captures_tempcomp(paths, t0: float | None = None) -> TempComp:
    """The per-element compensation (host.temperature.fit_tempcomp) from the captures at ``paths``, of one sensor
    through one channel map, each at the temperature its meta records; a pose is matched across them by value.
    ``t0``: one of their temperatures (default: as fit_tempcomp chooses). InputError for captures that do not
    go together."""
    if len(paths) < 2:
        raise InputError("give two or more captures, each taken at its own temperature")
    sets = [load_dataset(p, min_rows=1) for p in paths]
    first, name = sets[0], paths[0]
    for ds, path in zip(sets[1:], paths[1:]):
        for key, what in (("adc", "channel map (--adc)"), ("sensor_sha256", "simulated sensor")):
            if key in first.meta and ds.meta.get(key) != first.meta[key]:
                raise InputError(f"{path} was captured through another {what} than {name}: one compensation is "
                                 "for one sensor read one way")
        if ds.n_inputs != first.n_inputs or ds.target_names != first.target_names:
            raise InputError(f"{path} has other columns than {name}: capture each temperature with one schedule")
    temps = [_temperature(ds, p) for ds, p in zip(sets, paths)]
    if len({round(t, 1) for t in temps}) < 2:
        raise InputError(f"the captures were all read at {temps[0]:.1f} degC: give captures at two or more "
                         "temperatures")
    poses = np.vstack([ds.poses() for ds in sets])
    unique, pose_ids = np.unique(np.round(poses, 6), axis=0, return_inverse=True)
    at_rest = np.flatnonzero(np.all(contact_poses(unique) == 0, axis=1))
    tc = fit_tempcomp(np.vstack([ds.inputs for ds in sets]), pose_ids.ravel(),
                      np.concatenate([np.full(ds.n_rows, t) for ds, t in zip(sets, temps)]), t0=t0,
                      rest=int(at_rest[0]) if at_rest.size else None)
    tc.info["captures"] = [str(p) for p in paths]
    if isinstance(first.meta.get("adc"), str):  # the elements each coefficient is for: read and pi-build compare
        tc.info["adc"] = first.meta["adc"]
    return tc
