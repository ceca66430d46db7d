"""What identify and check take from a capture before they use it: the captures `capture --temperature` wrote in
its name's place, and its rows mapped to a temperature compensation's t0."""

from __future__ import annotations

import sys

from fitgen.base.errors import InputError


def not_levels(capture) -> None:
    """InputError naming the captures `capture --temperature -o CAPTURE` wrote, one per level, where ``capture``
    is not there but they are (it writes no file of that name)."""
    import glob
    from pathlib import Path

    path = Path(capture)
    levels = sorted(glob.glob(f"{glob.escape(str(path.with_suffix('')))}.T*{path.suffix or '.csv'}"))
    if levels and not path.exists():
        raise InputError(f"{capture}: no such file; capture --temperature wrote one capture per temperature under "
                         f"that name ({', '.join(Path(f).name for f in levels)}): give one of them (--temp-comp "
                         f"{path.stem}.tempcomp.json takes its rows to the compensation's t0)")


def at_t0(ds, tc, path: str, capture: str, command: str):
    """``ds``'s readings mapped to temperature compensation ``tc`` (read from ``path``)'s t0 from the temperature its capture recorded,
    and the unit file's record of it: the twin is then the unit at t0, as a readout with the compensation sees it.
    Notes on ``command``'s stderr, as a readout's: rows read where the compensation is extrapolated, and a
    compensation fitted through another channel map than the capture's."""
    from dataclasses import replace

    import numpy as np

    from fitgen.physics.dataset import row_degc, thermistor_degc
    from host.temperature import beyond_note, channel_map_note

    degc, rows = thermistor_degc(ds.meta), row_degc(ds.meta, ds.n_rows)
    if degc is None and rows is None:
        raise InputError(f"--temp-comp {path}: {capture} records no temperature (thermistor_degc: its channel map "
                         "had no thermistor, temp= in --adc), so there is nothing to compensate from")
    if ds.meta.get("units", "V") != "V" or tc.n != ds.n_inputs:
        raise InputError(f"--temp-comp {path} compensates {tc.n} elements in V; {capture} has {ds.n_inputs} in "
                         f"{ds.meta.get('units')}")
    temps = rows if rows is not None else np.full(ds.n_rows, degc)  # each row at its own, where recorded
    damaged = ("" if rows is not None or "row_degc" not in ds.meta else
               f"note: {capture}'s meta has a row_degc that does not hold one finite temperature for each of its "
               f"{ds.n_rows} rows (a capture stopped between a row and its meta, or edited): every row is compensated "
               f"from thermistor_degc, {degc:g} degC, read as the capture started")
    for note in (damaged, beyond_note(tc, temps, f"--temp-comp {path}", f"{capture}'s rows"),
                 channel_map_note(tc, ds.meta.get("adc"), f"--temp-comp {path}")):
        if note:
            print(f"{command}: {note}", file=sys.stderr)
    out = replace(ds, inputs=tc.apply(ds.inputs, temps))
    return out, {"capture_degc": tc.t0, "compensated_from_degc": round(float(np.median(temps)), 4)}
