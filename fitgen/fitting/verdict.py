"""What identify says of a capture: rows the stage's error may have lifted off the skin, the rows that stand out,
residuals far below the noise, a stage looser than it was taken for or a field it carries; and the refusal, in one
line, of a capture the physics does not explain (or does only with a unit far outside its tolerances), naming what to
blame (fitgen.fitting.blame) where one thing alone is."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from fitgen.base.errors import InputError
from fitgen.fitting.blame import FIELD_TRY, PRINTER_RIG, blame
from fitgen.fitting.capturecheck import check_error
from fitgen.fitting.identify import (CHI2_LIMIT, OUTLIER_LIMIT, PRIOR_LIMIT, RIG_ERROR, ZERO_ERROR, Identification,
                                     identify)
from fitgen.fitting.unitrecord import pose_words
from fitgen.physics.pose import OFF_SKIN_MM, POSE_NAMES, contact_top, lift_odds, lifted_zero, off_skin


def lifted_rows_line(poses: np.ndarray, rig_error: float, zero_error: float = 0.0) -> list[str]:
    """A line when rows in contact stand higher than a stage off by ``rig_error`` mm rms, zeroed within
    ``zero_error`` mm rms, keeps on the skin (fitgen.physics.pose.contact_top): how many, how often that stage lifts
    the highest past the adhesion (the magnet then reads at rest under a label that moves it), and the schedule that
    presses them. InputError for a rig or zero error identify refuses (fitgen.fitting.capturecheck.check_error)."""
    check_error("rig error", rig_error)
    check_error("zero error", zero_error)
    poses = np.asarray(poses)
    top = contact_top(rig_error, zero_error)
    high = ~off_skin(poses) & (poses[:, 2] > top)
    if not high.any():
        return []
    worst = float(poses[high, 2].max())
    odds = lift_odds(worst, rig_error, zero_error)
    if odds <= 0:  # a stage that errs nowhere keeps every row where it stands
        return []
    return [f"{int(high.sum())} rows in contact stand at dz up to {worst:g} mm, where a stage off by {rig_error:g} mm "
            f"rms, zeroed within {zero_error:g} mm, lifts about one in {1.0 / odds:,.0f} past the skin's adhesion "
            f"({OFF_SKIN_MM:g} mm) and the magnet reads at rest; a schedule made for this stage that moves dz (fitgen "
            f"schedule --rig-error {rig_error:g} --zero-error {zero_error:g}) presses them to {top:g} mm"]


def _where(ident: Identification, i: int) -> str:
    """Row ``i``'s line in the capture's file (the header is line 1), where an editor finds it, and its pose."""
    return f"line {i + 2}: {pose_words(ident, ident.problem.poses[i])}"


def outlier_lines(ident: Identification, capture, top: int = 3) -> list[str]:
    """One line per row of ``capture`` the physics does not explain (:meth:`Identification.outlying_rows`)."""
    rows = ident.outlying_rows()
    if not rows:
        return []
    rest = float(np.delete(ident.row_worst, [i for i, _ in rows]).max(initial=0.0))
    lines = [f"row {i + 1} of {capture} ({_where(ident, i)}) stands out: residuals up to {r:.3g} standard "
             f"deviations, the other rows at most {rest:.3g}; a slip, a knock or creep? delete the row and resume the "
             "capture to take that pose again" for i, r in rows[:top]]
    if len(rows) > top:
        lines.append(f"{len(rows) - top} more rows stand out beyond {OUTLIER_LIMIT:g} (the posterior lists them)")
    return lines


LOW_CHI2 = 0.3  # reduced chi-square below this: the errors the rows were weighed with are set too large


def low_residual_line(ident: Identification, source: str) -> list[str]:
    """A line when the residuals are far below what the noise figure and the stage's errors predict: one of those is
    set too large (or the rows carry no noise), and every standard error is too wide with it."""
    if ident.reduced_chi2 >= LOW_CHI2:
        return []
    return [f"the residuals are {float(np.sqrt(ident.reduced_chi2)):.2g}x what the reading noise ({source}) and the "
            "stage's errors predict: one of them is set too large (--noise, --rig-error, --zero-error), or the rows "
            "carry no noise, so the standard errors are too wide"]


# the zero found this many zero errors (rms per axis) off first contact on an axis, and as many standard errors: set
# off by more than the schedule was made for (within 0.15 mm below or aside, identify still finds it)
FAR_ZERO = 3.0


def far_zero_line(ident: Identification) -> list[str]:
    """A line when the capture's zero sat farther from first contact than the zero error its rows were scheduled and
    weighed for (:attr:`Identification.zero`): the next capture's first contact should be set again."""
    if ident.zero is None:
        return []
    mean, cov = ident.zero
    allowed = ident.problem.zero_error
    far = (np.abs(mean) > FAR_ZERO * allowed) & (np.abs(mean) > FAR_ZERO * np.sqrt(np.diag(cov)))
    if not far.any():
        return []
    at = ", ".join(f"{POSE_NAMES[j]} {mean[j]:+.3f} mm" for j in np.flatnonzero(far))
    return [f"the capture's zero sat {at} from first contact, beyond {FAR_ZERO:g}x the zero error its rows were "
            f"weighed with ({allowed:g} mm): the unit is read from first contact all the same, but a schedule keeps "
            "its rows on the skin only for a zero within its zero error (one set above first contact lifts the rows "
            "pressed least off it); set first contact again before the next capture (docs/calibration.md), or "
            "schedule and identify with a --zero-error as large"]


def taken_lifted_line(ident: Identification, labels: np.ndarray) -> list[str]:
    """A line when identify took rows labelled in contact as lifted off the skin (``Problem.lifted``; ``labels``:
    the capture's poses as labelled): which, and why."""
    prob = ident.problem
    rows = prob.lifted
    if not rows:
        return []
    top = float(np.max(np.asarray(labels)[list(rows), 2]))
    named = ", ".join(str(i + 1) for i in rows)
    at = (f", its zero found at dz {ident.zero[0][2]:+.3f} mm (standard error {np.sqrt(ident.zero[1][2, 2]):.2g}, "
          "which allows for the rows the rig's error kept on the skin beside them)" if ident.zero else "")
    return [f"row{'s' * (len(rows) > 1)} {named}, labelled in contact (dz up to {top:g} mm), read as the capture's "
            f"rows off the skin: the stage lifted {'them' if len(rows) > 1 else 'it'} past the skin's adhesion "
            f"({OFF_SKIN_MM:g} mm), its zero set above first contact. Taken as rows at rest, with a zero error in "
            f"dz of {prob.zero_sd[2]:.3g} mm (as far above first contact as they put the zero), the capture reads as "
            f"a unit within the tolerances, to the noise{at}; set first contact again before the next capture "
            "(docs/calibration.md)"]


def held_line(ident: Identification) -> list[str]:
    """A line when identify held readings out (``Problem.held``: its last start's): how many, and why."""
    held = ident.problem.held
    if held is None:
        return []
    rows = np.flatnonzero(held.any(axis=1))
    return [f"{int(held.sum())} readings of rows {', '.join(str(i + 1) for i in rows)} held out: a unit fitted for a "
            "stage three times looser puts them by a knee (an element's saturation, an ADC's rail, a field's zero), "
            "and one read across a knee had pulled the fit off the unit; without them the capture reads as a unit "
            "within the tolerances, to the noise (docs/calibration.md)"]


# an accepted capture's reduced chi-square above this: does a looser stage, or a field the stage carries, explain it?
FIELD_HINT_CHI2 = 1.3
# a row carrying this share of the chi-square or more: the excess is that row's (a slip: its line names it), not
# every row's, as a looser stage's is (a stage of 0.025 mm taken for 0.01: at most 0.09; a row slipped 0.15 mm: 0.4)
ONE_ROW_SHARE = 0.2


def _halves_excess(ident: Identification, again: Identification) -> bool:
    """Whether ``again`` (the capture identified once more, allowing for one more cause) brings the reduced
    chi-square's excess over 1 down by half or more."""
    return again.reduced_chi2 <= 1.0 + (ident.reduced_chi2 - 1.0) / 2.0


def looser_stage_line(ident: Identification, progress=None) -> list[str]:
    """A line when an accepted capture's reduced chi-square sits above FIELD_HINT_CHI2 spread over its rows (none
    carries ONE_ROW_SHARE of it), its rig error is under a printer's (PRINTER_RIG) and a printer's halves the excess
    over 1: the stage is looser than it was taken for, and the standard errors, and the twin's figures they widen,
    are too narrow. One more identification, only then."""
    prob = ident.problem
    if prob.rig_error >= PRINTER_RIG or ident.reduced_chi2 <= FIELD_HINT_CHI2 or ident.row_chi2.max() >= ONE_ROW_SHARE:
        return []
    again = identify(prob.space.drawing, prob.readings, prob.poses, prob.noise, rig_error=PRINTER_RIG,
                     zero_error=prob.zero_error, progress=progress)
    if not _halves_excess(ident, again):
        return []
    return [f"the stage's own error explains the rows better allowed for as {PRINTER_RIG:g} mm rms per axis (a 3D "
            f"printer's) than as {prob.rig_error:g}: reduced chi-square {again.reduced_chi2:.2f} against "
            f"{ident.reduced_chi2:.2f}; give --rig-error {PRINTER_RIG:g}, or the stage's measured repeatability, or "
            "the standard errors, and the twin's figures they widen, are too narrow"]


def field_line(ident: Identification, progress=None) -> list[str]:
    """A line when an accepted capture's reduced chi-square sits above FIELD_HINT_CHI2 and a field that moves with the
    stage, allowed for (FIELD_TRY), halves its excess over 1: bench/stage_field.py's silent zone, where the twin
    loses 10-20 %. One more identification, only then."""
    prob = ident.problem
    if prob.space.moving_field or ident.reduced_chi2 <= FIELD_HINT_CHI2:
        return []
    d = prob.space.drawing
    again = identify(replace(d, tolerances=replace(d.tolerances, stage_field=FIELD_TRY)), prob.readings, prob.poses,
                     prob.noise, rig_error=prob.rig_error, zero_error=prob.zero_error, progress=progress)
    if not _halves_excess(ident, again):
        return []
    return [f"a field that moves with the stage (its motors, a steel bed) explains the rows better: reduced "
            f"chi-square {again.reduced_chi2:.2f} against {ident.reduced_chi2:.2f}; give the drawing [tolerances] "
            f"stage_field = {FIELD_TRY:g}, schedule and identify with it (docs/calibration.md)"]


def stage_error_hint(ident: Identification) -> str:
    """'' when the identification allowed for the stage's error as fitgen identify does by default; else the
    refusal's first cause: the stage's own error, which a rig or zero error below the default leaves unexplained."""
    prob = ident.problem
    given = [(flag, value, default) for flag, value, default in
             (("--rig-error", prob.rig_error, RIG_ERROR), ("--zero-error", prob.zero_error, ZERO_ERROR))
             if value < default]
    if not given:
        return ""
    flags = " and ".join(f"{flag} {value:g}" for flag, value, _ in given)
    defaults = " and ".join(f"{default:g}" for _, _, default in given)
    both = len(given) > 1
    return (f"likely the stage's own error, which {flags} (below the default{'s' if both else ''}, {defaults} mm) "
            f"leave{'' if both else 's'} unexplained: try the default{'s' if both else ''} or the stage's measured "
            "error; else ")


def axis_fix(m: np.ndarray) -> str:
    """What the capture's axis map needs for poses turned by ``m`` (a symmetry's matrix) to be the labels: each
    pose axis written for another, signed; or why no axis map can (a turn that is no multiple of 90 deg)."""
    cols = np.round(m[:2, :2]).astype(int)
    if not np.allclose(m[:2, :2], cols, atol=1e-9):
        return "no axis map turns or mirrors the stage's axes so: turn the sensor on the stage, or fix the channel map"
    names = ("dx", "dy")
    said = [f"{'-' if cols[:, j].sum() < 0 else ''}{names[int(np.abs(cols[:, j]).argmax())]} for {names[j]}"
            for j in range(2) if cols[j, j] != 1]
    return f"in the capture's axis map, --stage-axes, put {' and '.join(said)}, signs multiplying, and capture again"


def mirrored_axes(ident: Identification, far) -> list[str]:
    """The pose axes along which the nearest unit's magnet moves against the stage (a diagonal of its stage map
    below 0, among the parameters ``far`` outside the tolerances): a stage axis mirrored in the capture's map."""
    diag = np.diag(ident.unit().stage_map)
    named = {ident.space.names[i] for i, _ in far}
    return [a for k, a in enumerate(("dx", "dy", "dz")) if diag[k] < 0 and f"stage.m{k + 1}{k + 1}" in named]


class ChannelOrderError(InputError):
    """A refusal that names the order the capture's channels read the ring in: ``order[j]`` is the column that
    reads as element j+1 (0-based), so that the layer that knows the capture's channel map can write it so."""

    def __init__(self, message: str, order):
        super().__init__(message)
        self.order = tuple(int(k) for k in order)


def check_explained(ident: Identification, capture, drawing: str, source: str, progress=None,
                    lifted: tuple = ()) -> None:
    """InputError when the physics does not explain the capture (reduced chi-square over CHI2_LIMIT), or does only
    with a unit far outside its tolerances (a parameter beyond PRIOR_LIMIT spreads), with the cause when one thing
    alone is to blame (rows, an element, a field the stage carries, the ring's order, a swapped pair:
    :func:`fitgen.fitting.blame.blame`, ``progress`` its callback) or the stage's axes are; ``source``: where the
    reading noise came from; ``drawing``: the sensor's name; ``lifted``: rows in contact that read at rest, which
    taken as lifted did not explain the capture either (named where nothing else is). Where the channels' order is to
    blame, the error is a :class:`ChannelOrderError`, carrying the order."""
    far, bad = ident.outside_tolerances(), ident.reduced_chi2 > CHI2_LIMIT
    if not (bad or far):
        return
    names = ", ".join(f"{ident.space.names[i]} at {z:+.3g}" for i, z in far[:3]) + " prior spreads"
    culprit = blame(ident, progress)
    order = None  # the columns' order that explains the capture, where blame found the channels in another
    if culprit is not None and culprit[0] == "rows":
        rows = culprit[1]
        it, they = ("it", "it") if len(rows) == 1 else ("them", "they")
        cause = (f"{_rows(ident, rows)} alone: with {it} left out, the others read as a unit within the tolerances, to "
                 f"the noise; if {they} slipped or glitched, {_delete(rows)}")
    elif culprit is not None and culprit[0] == "rig":
        rig, rows = culprit[1]
        cause = (f"the stage's own error: allowed for as {rig:g} mm rms per axis (a 3D printer's) instead of "
                 f"{ident.problem.rig_error:g}, the capture reads as a unit within the tolerances, to the noise"
                 + (f", with {_rows(ident, rows)} left out" if rows else "") + f"; give --rig-error {rig:g}, or the "
                 "stage's measured repeatability" + (f", and {_delete(rows)}" if rows else ""))
    elif culprit is not None and culprit[0] == "dead":
        k = culprit[1][0]
        cause = (f"element {k + 1} (v{k + 1}) alone: with its readings left out, the others read as a unit within the "
                 "tolerances, to the noise; it does not respond, or is wired to another channel (the channel map)")
    elif culprit is not None and culprit[0] == "field":
        cause = (f"a field that moves with the stage (its motors, a steel bed): allowed for ([tolerances] stage_field "
                 f"= {FIELD_TRY:g} mT/mm in the drawing's file), the capture reads as a unit within the tolerances, to "
                 "the noise; give the drawing that tolerance, schedule and identify with it (docs/calibration.md)")
    elif culprit is not None and culprit[0] == "ring":
        what, order, m = culprit[1]
        taken = ", ".join(f"v{k + 1}" for k in order)
        cause = (f"the channels against the ring, or the stage's axes against the sensor's: taken in the order {taken} "
                 f"as elements 1-{len(order)} (the ring {what}), the readings are a unit within the tolerances, to "
                 "the noise; the elements are wired in that order (the channel map"
                 + ("; two ADCs of four exchanged turn a ring of eight by 180 deg"
                    if np.allclose(m, np.diag([-1.0, -1.0, 1.0])) and len(order) == 8 else "")
                 + "), or the sensor sits turned on the stage or a pose axis is mirrored or swapped (" + axis_fix(m) + ")")
    elif culprit is not None:
        a, b = culprit[1]
        order = [b if k == a else a if k == b else k for k in range(ident.space.drawing.n_elements)]
        cause = (f"elements {a + 1} and {b + 1} (v{a + 1}, v{b + 1}) swapped: with their readings exchanged, the capture "
                 "reads as a unit within the tolerances, to the noise; their channels are wired the other way round "
                 "(the channel map)")
    elif flipped := mirrored_axes(ident, far):
        cause = (f"the stage's {' and '.join(flipped)} against the sensor's: the nearest unit moves its magnet against "
                 "the stage along " + ("it" if len(flipped) == 1 else "them") + "; in the capture's axis map, "
                 f"--stage-axes, put {' and '.join(f'-{a} for {a}' for a in flipped)}, signs multiplying, and capture "
                 "again")
    elif far and all(ident.space.names[i].startswith("stage.") for i, _ in far[:3]):
        cause = ("the stage's axes against the sensor's: a pose axis mirrored, swapped or in other units than mm "
                 "(the capture's axis map, --stage-axes)")
    elif lifted:  # rows in contact that read at rest, which taken as lifted (capturezero.lifted_rows) did not explain
        top = float(np.max(ident.problem.poses[list(lifted), 2]))
        least = lifted_zero(ident.problem.poses, lifted)
        cause = (f"{len(lifted)} rows labelled in contact (rows {', '.join(str(i + 1) for i in lifted)}; dz up to "
                 f"{top:g} mm) read as the capture's rows off the skin: the stage lifted them past the skin's "
                 f"adhesion, its zero set at least {least:.3g} mm above first contact; " + (
                     "taken as rows at rest they leave the capture unexplained all the same, the zero farther above "
                     "first contact than the rows in contact can tell: set first contact again (docs/calibration.md) "
                     "and capture again" if ident.problem.zero_error > 0 else
                     f"--zero-error 0 allows none: identify with a zero error (the default {ZERO_ERROR:g} mm) to "
                     "take them as lifted, or set first contact again (docs/calibration.md) and capture again"))
    else:
        cause = None
    if bad:
        rows = ident.outlying_rows()
        at_rest = bool(rows) and bool(off_skin(ident.problem.poses[rows[0][0]][None])[0])
        row = "" if not rows else (f"; row {rows[0][0] + 1} stands out most ({_where(ident, rows[0][0])}; residuals up "
                                   f"to {rows[0][1]:.3g} standard deviations)" + (
                                       ", a row at rest that no stage error moves: the rows in contact disagree with "
                                       "it" if at_rest else ": if it slipped, delete it and resume")
                                   if len(rows) <= 3 else f"; {len(rows)} rows stand out, not one")
        cause = cause or (stage_error_hint(ident) + f"another sensor than {drawing}, labels in other units, an element "
                          "that does not respond or "
                          "elements wired in another order than the drawing's (the channel map), a zero off first "
                          "contact (above it, the rows pressed least off the skin; below it or aside, every row pressed or "
                          f"slid by as much), or a noise figure too low{row}")
        raise _refusal(f"the physics does not explain {capture}: residuals {float(np.sqrt(ident.reduced_chi2)):.3g}x "
                       f"the reading noise ({source}); {cause}"
                       + (f"; the nearest unit lies far outside the tolerances ({names})" if far else "")
                       + "; nothing written", order)
    cause = cause or ("an element that does not respond or is wired to another channel, another sensor than "
                      f"{drawing}, or a unit built looser than its [tolerances] say (widen them in the drawing's file)")
    raise _refusal(f"the physics explains {capture} only with a unit far outside {drawing}'s tolerances ({names}; "
                   f"beyond {PRIOR_LIMIT:g} is no unit within them): {cause}; nothing written", order)


def _rows(ident: Identification, rows) -> str:
    """``rows`` (0-based) as a refusal names them: number, line and pose."""
    return "; ".join(f"row {i + 1} ({_where(ident, i)})" for i in rows)


def _delete(rows) -> str:
    """What to do with rows a refusal names as slipped or lifted."""
    return f"delete {'it' if len(rows) == 1 else 'them'} and resume the capture (it takes the pose again)"


def _refusal(message: str, order) -> InputError:
    return InputError(message) if order is None else ChannelOrderError(message, order)
