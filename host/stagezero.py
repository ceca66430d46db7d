"""The zero of a stage run and what survives between runs: the state file beside the dataset.

``StageState`` keeps the zero and the last position beside the dataset
(``<output>.stage.json``) so that a resumed capture knows whether the controller
was reset meanwhile; ``choose_zero`` keeps that zero while it holds, else takes
it from ``--zero`` (``parse_zero``) or asks for it again.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fitgen.base.errors import InputError
from fitgen.base.fileio import write_atomic

from host.gcode import MACHINE_AXES, POSITION_TOL, GcodeController
from host.stagesettings import AxisMap


@dataclass
class StageState:
    """What a resumed capture needs of the stage: the zero, and where the last moves left it."""

    flavor: str
    axes: str
    zero: dict  # machine axis -> mm: the pose origin (first contact with the resting sensor)
    homed: bool  # the zero was taken on a homed machine: it holds after a reset and homing
    position: list | None = None  # machine X, Y, Z after the last confirmed move
    pending: list = field(default_factory=list)  # targets sent but not confirmed (a run stopped mid-move)
    lost: str = ""  # why a run lost the machine's position (a reset, an alarm, a halt): the zero no longer holds

    @staticmethod
    def path_for(output: str | Path) -> Path:
        return Path(str(output) + ".stage.json")

    def save(self, output: str | Path) -> None:
        write_atomic(self.path_for(output), json.dumps(self.__dict__, indent=2, sort_keys=True) + "\n")

    @classmethod
    def load(cls, output: str | Path) -> "StageState | None":
        path = cls.path_for(output)
        if not path.exists():
            return None
        try:
            d = json.loads(path.read_text())
            zero = {str(k): _coordinate(v) for k, v in d["zero"].items()}
            mapped = [m for m, _, _ in AxisMap.parse(str(d["axes"])).pairs]
            if set(zero) != set(mapped):  # a move is sent from these: every mapped axis, nothing else
                raise ValueError(f"its zero gives {','.join(sorted(zero)) or 'no axis'} for the axes {','.join(mapped)}")
            position = None if d.get("position") is None else _xyz(d["position"])
            pending = [_xyz(t) for t in (d.get("pending") or [])]
            return cls(str(d["flavor"]), str(d["axes"]), zero, bool(d["homed"]), position, pending,
                       str(d.get("lost") or ""))
        except (OSError, ValueError, KeyError, TypeError, AttributeError, OverflowError, InputError) as exc:
            raise InputError(f"{path}: not a stage state as tactile-host capture writes it ({exc}); remove it to set "
                             "the zero again") from None

    @classmethod
    def mark_lost(cls, output: str | Path, why: str) -> None:
        """Record beside ``output`` that its run lost the machine's position (``why``), if it had a zero."""
        state = cls.load(output)
        if state is not None:
            state.lost = why
            state.save(output)


def _coordinate(v) -> float:
    """A machine coordinate from a state file: a finite number within MAX_COORD (ValueError otherwise): the zero
    is where every move is sent from, and a damaged one drove a stage toward X 1,000,000 or sent 'G1 Xnan'."""
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not abs(v) <= MAX_COORD:  # NaN, huge ints too
        raise ValueError(f"{v!r:.30} is no machine coordinate (a number within {MAX_COORD:g} mm)")
    return float(v)


def _xyz(p) -> list[float] | dict[str, float]:
    """A position (X, Y, Z) or a pending target (the mapped axes by name) from a state file (ValueError
    otherwise)."""
    if isinstance(p, dict) and p and set(p) <= set(MACHINE_AXES):
        return {a: _coordinate(v) for a, v in p.items()}
    if isinstance(p, list) and len(p) == len(MACHINE_AXES):
        return [_coordinate(v) for v in p]
    raise ValueError(f"{p!r:.40} is no machine position (X, Y, Z)")


KEPT = "kept from the last run"  # choose_zero's word for a zero that holds


def zero_still_valid(state: StageState | None, ctrl: GcodeController, axes: AxisMap, homed_now: bool) -> str:
    """'' if ``state``'s zero holds for this connection, else why not (one clause)."""
    if state is None:
        return "the stage has no zero yet"
    if state.axes != str(axes):
        return f"the zero was taken with --stage-axes {state.axes}"
    if state.flavor != ctrl.flavor:
        return f"the zero was taken on a {state.flavor} controller"
    if state.homed and homed_now:
        return ""  # homing gives the same machine coordinates after any reset
    if state.lost:
        # the controller may report the very target the last run sent, reached in coordinates it reset
        return f"the last run lost the stage's position ({state.lost})"
    if homed_now:
        return "homing moved the machine since the zero was taken (the zero was set before homing)"
    if ctrl.banner_seen:
        return "the controller was reset (it printed its start-up banner on connect)"
    pos = ctrl.position()
    known = ([state.position] if state.position is not None else []) + list(state.pending)
    for p in known:
        # a pending target names the mapped axes only; the others never move
        p = np.array([p.get(a, np.nan) for a in MACHINE_AXES]) if isinstance(p, dict) else np.asarray(p, dtype=float)
        want = [MACHINE_AXES.index(m) for m, _, _ in axes.pairs]
        if np.all(np.abs(pos[want] - p[want]) <= POSITION_TOL):
            return ""
    where = " ".join(f"{a}{v:g}" for a, v in zip(MACHINE_AXES, pos))
    return (f"the controller reports {where}, not where the last run left it: it was reset or moved since the "
            "zero was taken")


MAX_COORD = 2000.0  # mm: past the travel of any machine this drives (printers, desk CNCs: under a metre)


def parse_zero(spec: str) -> str | dict[str, float]:
    """``ask``, ``here``, or machine coordinates ``X=..,Y=..,Z=..``, G-code words ``X.. Y.. Z..`` (as stage-sim
    prints them), M114's answer as printed (``X:.. Y:.. Z:.. E:.. Count X:..``: its steps and extruder left out) or
    three numbers."""
    s = spec.strip().lower()
    if s in ("ask", "here"):
        return s
    from fitgen.base.parse import parse_assignments

    if re.match(r"\s*x\s*:", s):  # M114's line: the position before "Count" (the steppers' counts), no extruder
        s = re.sub(r"\be\s*:\s*\S*", " ", re.split(r"\bcount\b", s)[0])
    words = re.fullmatch(r"(?:\s*[xyz]\s*:?\s*[-+.\d][^\s,;xyz]*[\s,;]*)+", s) if "=" not in s else None
    if "=" in s or words:
        text = (re.sub(r"([xyz])\s*:?\s*(?=[-+.\d])", r" \1=", s) if words else s).upper()  # X1Y2Z3 too
        try:
            vals = parse_assignments(text, MACHINE_AXES, "--zero")
        except InputError as exc:  # said of the words as given
            raise InputError(str(exc).replace(repr(text), repr(spec), 1)) from None
    else:
        try:
            nums = [float(x) for x in s.replace(",", " ").split()]
        except ValueError:
            nums = []
        if len(nums) != 3:
            raise InputError(f"--zero {spec!r}: ask, here, or the machine coordinates X,Y,Z (e.g. 120.5,80,12.25 or "
                             "X120.5 Y80 Z12.25)")
        vals = dict(zip(MACHINE_AXES, nums))
    if not all(math.isfinite(v) for v in vals.values()):
        raise InputError(f"--zero {spec!r}: not finite")
    far = [f"{m}{v:g}" for m, v in vals.items() if abs(v) > MAX_COORD]
    if far:  # said before anything moves: the machine would drive for its end, its move's time limit years away
        raise InputError(f"--zero {spec!r}: {' '.join(far)} lies over {MAX_COORD:g} mm from the machine's origin, past "
                         "any printer's or desk CNC's travel: a slipped decimal point? (machine coordinates in mm, as "
                         "M114 or GRBL's ? report them)")
    return vals


def choose_zero(ctrl: GcodeController, state: StageState | None, axes: AxisMap, spec, *, rows: int,
                ask) -> tuple[dict[str, float], str]:
    """The zero for this run and how it was had: kept from ``state`` while it holds, else from ``spec``
    (``ask``: ``ask(reason)`` jogs with the user; ``here``: the current position, for a dataset without
    rows only; or machine coordinates). Raises InputError when none can be had. A dataset without rows keeps no
    zero: ``state`` is then an earlier capture's of that name (deleted since), not this one's."""
    if not rows:  # the old zero kept, a new unit seated since would have been pressed from it, --zero here unheard
        state = None
    reason = zero_still_valid(state, ctrl, axes, ctrl.homed)
    if isinstance(spec, dict):
        want = [m for m, _, _ in axes.pairs]
        missing = [m for m in want if m not in spec]
        if missing:
            raise InputError(f"--zero: give {missing[0]} too (it is in --stage-axes {axes})")
        zero = {m: float(spec[m]) for m in want}
        if not reason and rows and any(abs(zero[m] - state.zero[m]) > POSITION_TOL for m in want):
            raise InputError(f"--zero {' '.join(f'{m}{v:g}' for m, v in zero.items())} is not the zero the dataset's "
                             f"{rows} rows were taken from ({' '.join(f'{m}{v:g}' for m, v in state.zero.items())}); "
                             "choose another -o for another zero")
        # the same numbers after a reset need not be the same place (a machine not homed counts from where it woke)
        return zero, (f"given again: {reason}" if reason and rows else "given")
    if not reason:
        return dict(state.zero), KEPT
    if spec == "here":
        if rows:
            raise InputError(f"{reason}; --zero here takes the zero only for a dataset without rows (the stage "
                             "may stand anywhere now): set it at the prompt (--zero ask) or give --zero X,Y,Z")
        pos = ctrl.position()
        return {m: float(pos[MACHINE_AXES.index(m)]) for m, _, _ in axes.pairs}, "here"
    zero = ask(reason)
    if zero is None:
        raise InputError(f"{reason}, and no zero was set: set it at the prompt, or give --zero X,Y,Z "
                         "(machine coordinates of first contact)")
    return zero, "set by jogging"


def run_zeros(prior: dict, zero: dict[str, float], how: str = KEPT) -> list[dict]:
    """Every zero a capture's runs moved from, as its meta records them (``prior``: the meta of its rows so far,
    {} without rows), with this run's ``zero`` last: one entry while the zero holds, more when a run had to set it
    again (a controller reset; ``how``: :func:`choose_zero`'s word, so that the same numbers given again count),
    which fitgen identify and fitgen check then say."""
    st = prior.get("stage") if isinstance(prior.get("stage"), dict) else {}
    old = st.get("zeros_machine_mm")
    if not isinstance(old, list):
        old = [st["zero_machine_mm"]] if "zero_machine_mm" in st else []
    old = [z for z in old if isinstance(z, dict)]
    again = how not in (KEPT, "given")  # set again by jogging, "here" or given again after the zero was lost
    if not old or again or any(old[-1].get(k) != v for k, v in zero.items()):
        old = old + [dict(zero)]
    return old
