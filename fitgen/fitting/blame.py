"""What to blame for a capture the physics does not explain within the tolerances, when one thing alone is: rows that
slipped or glitched, a stage looser than the rig error allowed, an element that does not respond, a field the stage
carries, the ring read turned or mirrored (the channels in another order than the drawing's, or the sensor turned
against the stage's axes), two elements' channels exchanged. Each trial undoes one fault and fits again, briefly
(fitgen.fitting.identify.explained_within); a fault is named only when it alone of its kind explains the capture.
"""

from __future__ import annotations

from dataclasses import replace
from itertools import combinations, count

import numpy as np

from fitgen.fitting.identify import Identification, Problem, explained_within
from fitgen.physics.units import UnitSpace, symmetries

ROW_SUSPECTS, ROW_SHARE = 3, 0.1  # rows tried left out before elements: at most 3, each a tenth of the chi-square
FIELD_TRY = 0.003  # mT/mm: the trial of a field the stage carries (bench/stage_field.py)
PRINTER_RIG = 0.03  # mm rms per axis: the trial of a stage as loose as a 3D printer (fitgen identify --rig-error)


def _reordered(prob: Problem, order) -> Problem:
    """``prob`` with element k's readings taken from column ``order[k]``."""
    order = np.asarray(order)
    return replace(prob, readings=prob.readings[:, order], valid=prob.valid[:, order], noise=prob.noise[order])


def blame(ident: Identification, progress=None) -> tuple[str, tuple] | None:
    """What to blame for a capture the physics does not explain within the tolerances, when one thing alone is:
    ``("rows", (i, ...))``, the one to three rows that stand out, when the others without them read as a unit within
    its tolerances to the noise (a slip, a glitch: tried first, as one bad reading also leaves its element to blame);
    else ``("rig", (PRINTER_RIG, rows))`` when they do with a printer's rig error, for a capture identified with a
    smaller one (the stage is looser than it was taken for), all of them or without the ``rows`` that stand out (a
    loose stage also slips); else ``("dead", (k,))``, the one element whose readings, left out, do (it does not
    respond, or is wired to another channel); else ``("field", ())`` when they do with a field the stage carries
    allowed for (its motors, a steel bed); else ``("ring", symmetry)``, the one symmetry of the drawing (turn or
    mirror, fitgen.physics.units.Symmetry) whose element order does, tried when more than three rows stand out or the
    stage map lies far out (a ring read turned reads as a sensor turned on the stage: the same readings); else
    ``("swapped", (a, b))``, the one pair of elements whose readings, exchanged, do (their channels wired the other
    way round), tried when more than three rows stand out, or among the elements that lie far out (neighbours
    exchanged read to the noise as two elements on each other's places); else None. One short fit per trial: with the
    fault undone a capture converges in a few steps. ``progress(i, n, note)`` before each."""
    prob = ident.problem
    n_el = prob.readings.shape[1]
    far = {ident.space.names[i].partition(".")[0] for i, _ in ident.outside_tolerances()}
    many = len(ident.outlying_rows()) > 3
    turns = symmetries(prob.space.drawing) if many or "stage" in far else []
    pairs = [(a, b) for a, b in combinations(range(n_el), 2) if many or {f"e{a + 1}", f"e{b + 1}"} <= far]
    share = ident.row_chi2
    top = [int(i) for i in np.argsort(-share, kind="stable")[:ROW_SUSPECTS] if share[i] >= ROW_SHARE]
    trials = [top[:1], top] if len(top) > 1 else [top] if top else []
    looser = prob.rig_error < PRINTER_RIG
    total, done = n_el + len(turns) + len(pairs) + (1 + looser) * len(trials) + 1 + looser, count(1)

    def trying(note: str) -> None:
        if progress is not None:
            progress(next(done), total, note)

    for rows in trials:
        trying(f"row{'s' * (len(rows) > 1)} {', '.join(str(i + 1) for i in rows)} left out")
        valid = prob.valid.copy()
        valid[rows] = False
        if explained_within(replace(prob, valid=valid)):
            return ("rows", tuple(rows))
    # before the elements: a stage's error spreads over every row, while a fault of one element's stays out of the
    # three directions per row that the stage's moves read in, so the looser rig does not explain it. All rows: from
    # the unit found, near; rows left out: from the drawing, the unit found having bent to them, and a second sweep
    # whatever the first's chi-square (a capture a printer lost the skin in lands near 80 after one, 1.2 after two)
    for rows in [[]] + trials if looser else []:
        trying(f"a stage error of {PRINTER_RIG:g} mm" + "".join(f", row {i + 1} left out" for i in rows))
        valid = prob.valid.copy()
        valid[rows] = False
        if explained_within(replace(prob, rig_error=PRINTER_RIG, valid=valid), None if rows else ident.theta,
                            resweep=np.inf):
            return ("rig", (PRINTER_RIG, tuple(rows)))
    found = []
    for k in range(n_el):
        trying(f"v{k + 1} left out")
        valid = prob.valid.copy()
        valid[:, k] = False
        if explained_within(replace(prob, valid=valid)):
            found.append(k)
    if found:
        return ("dead", (found[0],)) if len(found) == 1 else None
    d = prob.space.drawing
    trying("a field the stage carries")
    if not prob.space.moving_field and explained_within(replace(prob, space=UnitSpace.of(
            d, replace(d.tolerances, stage_field=FIELD_TRY)))):
        return ("field", ())
    for turn in turns:
        trying(f"the ring {turn.what}")
        if explained_within(_reordered(prob, turn.order)):
            found.append(turn)
    if found:
        return ("ring", found[0]) if len(found) == 1 else None
    for a, b in pairs:
        trying(f"v{a + 1} and v{b + 1} exchanged")
        order = np.arange(n_el)
        order[[a, b]] = order[[b, a]]
        if explained_within(_reordered(prob, order)):
            found.append((a, b))
    return ("swapped", found[0]) if len(found) == 1 else None
