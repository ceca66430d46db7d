"""A G-code stage (Marlin or GRBL over pyserial) that sets each pose of a capture by itself.

Four modules, lowest first. ``host.gcode.GcodeController`` speaks the line protocol
and each controller's dialect. ``host.stagesettings`` holds the signed axis map,
the soft limits and the approach. Here ``PoseStage`` moves in pose axes: the user's
zero, the soft limits checked before anything is sent, and every pose approached
from the same side so that backlash lags every pose alike; ``jog_to_zero`` lets the
user jog it to first contact. ``host.stagezero`` chooses the zero and keeps it, with
the last position, beside the dataset (``<output>.stage.json``) so that a resumed
capture knows whether the controller was reset meanwhile, and asks for the zero again if so.

Faults of the controller raise ``StageError`` (the CLI: one line, exit status 1,
rows kept); bad settings raise ``InputError`` before any motion.
"""

from __future__ import annotations

import math

import numpy as np

from fitgen.base.errors import InputError
from fitgen.physics.pose import OFF_SKIN_MM

from host.gcode import MACHINE_AXES, GcodeController, StageError, stage_url
from host.prompt import ask_line
from host.stagesettings import STAGE_AXES, AxisMap, StageSettings, parse_approach, parse_ranges
from host.stagezero import StageState, choose_zero, parse_zero

# fitgen/app/host_cli.py imports the stage's names from here, wherever they live
__all__ = ["AxisMap", "GcodeController", "PoseStage", "StageError", "StageSettings", "StageState", "choose_zero",
           "jog_to_zero", "parse_approach", "parse_ranges", "parse_zero", "stage_url"]


SAME = 6e-4  # mm: two displacements this close are one (moves are sent to 0.001 mm)
# Where a finished capture leaves the indenter (mm above first contact, or the limit's top where lower): its last
# rows press millimetres deep, where the elastomer creeps under load and a jog sideways drags the tool through it.
LIFT_MM = 1.0


class PoseStage:
    """Moves the controller to poses (dx, dy, dz from the zero), within the limits, each from the same side.

    An axis whose last move went the approach's way (towards the pose from the approach point) is
    "loaded": its backlash is taken up on that side. A pose is reached by one move when every axis
    moves that way or stays; otherwise by a move to the approach point first.
    """

    def __init__(self, ctrl: GcodeController, settings: StageSettings, zero: dict[str, float], *,
                 on_move=None):
        self.ctrl, self.settings, self.zero = ctrl, settings, dict(zero)
        self.on_move = on_move  # called with (list of machine targets about to be sent) and then (None)
        self.position: np.ndarray | None = None  # machine X, Y, Z last confirmed
        self.loaded = np.zeros(3, dtype=bool)
        self.moves = 0

    def _check(self, d: np.ndarray) -> None:
        for name in self.settings.axes.pose_axes:
            k = STAGE_AXES.index(name)
            lo, hi = self.settings.limits[name]
            if not lo - 1e-9 <= d[k] <= hi + 1e-9:
                # checked for the whole schedule before the first move: reaching this is a bug, never sent
                raise StageError(f"refused to move to {name}={d[k]:g}: outside the limits {lo:g}:{hi:g}")

    def plan(self, pose) -> list[np.ndarray]:
        """The pose displacements to send, the approach point first if one is needed."""
        target = np.asarray(pose, dtype=float)[:3].copy()
        a = self.settings.approach
        current = None if self.position is None else self.settings.axes.to_pose(self.zero, self.position)
        # a pose repeated goes away to the approach point and back, so the row has its own landing error (a
        # schedule's repeats are weighed as independent visits), not the last row's again
        repeat = current is not None and bool(np.all(np.abs(target - current) <= SAME))
        need = np.zeros(3, dtype=bool)
        for name in self.settings.axes.pose_axes:
            k = STAGE_AXES.index(name)
            if a[k] == 0:
                continue
            if current is None or repeat:
                need[k] = True  # where the backlash sits is unknown, or a fresh landing is wanted
                continue
            step = target[k] - current[k]
            towards = step * -np.sign(a[k]) > SAME  # moving the approach's way
            # loaded and staying or moving on the approach's way: still loaded; a move the approach's way
            # at least as long as the approach loads the axis too
            need[k] = not ((self.loaded[k] and (abs(step) <= SAME or towards)) or
                           (towards and abs(step) >= abs(a[k]) - SAME))
        if not need.any():
            return [target]
        return [np.where(need, target + a, target), target]

    def move_to(self, pose) -> None:
        self._go(self.plan(pose))
        for name in self.settings.axes.pose_axes:
            self.loaded[STAGE_AXES.index(name)] = True

    def _go(self, steps: list[np.ndarray]) -> None:
        """Move through pose displacements ``steps``, each checked against the limits before the first is sent,
        ``on_move`` told the machine targets before and None after."""
        for d in steps:
            self._check(d)
        targets = [self.settings.axes.to_machine(self.zero, d) for d in steps]
        if self.on_move is not None:
            self.on_move(targets)
        for t in targets:
            self.position = self.ctrl.move(t, self.settings.feed, start=self.position)
            self.moves += 1
        if self.on_move is not None:
            self.on_move(None)

    def lift(self) -> float | None:
        """After the last pose: the indenter straight up in dz to LIFT_MM above first contact, or the limits' top
        where lower, so that nothing stays pressed into the skin; the dz it went to, or None where it did not move
        (dz not among the stage's axes, a limit that allows no lift off the skin, or already there)."""
        if "dz" not in self.settings.axes.pose_axes or self.position is None:
            return None
        top = min(LIFT_MM, self.settings.limits["dz"][1])
        here = self.settings.axes.to_pose(self.zero, self.position)
        if top <= OFF_SKIN_MM or here[STAGE_AXES.index("dz")] >= top - SAME:
            return None
        target = np.array(here, dtype=float)
        target[STAGE_AXES.index("dz")] = top
        self._go([target])
        self.loaded[STAGE_AXES.index("dz")] = False  # against the approach: the next pose comes from above again
        return float(top)

    def jog(self, axis: str, step: float) -> np.ndarray:
        """A relative move along a pose axis while the zero is set (no limits: they count from the zero)."""
        if axis not in self.settings.axes.pose_axes:
            raise InputError(f"{axis} is not moved by --stage-axes {self.settings.axes}")
        if not math.isfinite(step):
            raise InputError(f"a jog step is a number of mm, got {step}")
        if abs(step) > self.settings.jog_max:
            raise InputError(f"a jog step is at most {self.settings.jog_max:g} mm")
        pos = self.position if self.position is not None else self.ctrl.position()
        here = {m: float(pos[MACHINE_AXES.index(m)]) for m, _, _ in self.settings.axes.pairs}
        d = np.zeros(3)
        d[STAGE_AXES.index(axis)] = step
        target = self.settings.axes.to_machine(here, d)
        self.position = self.ctrl.move(target, self.settings.feed, start=pos)
        self.loaded[:] = False
        return self.position


def jog_to_zero(stage: PoseStage, stdin, stderr, prog: str) -> dict[str, float] | None:
    """Ask the user to jog to first contact with the resting sensor; the zero, or None if they stop."""
    axes = stage.settings.axes
    stderr.write(f"{prog}: set the zero: jog the indenter to first contact with the resting sensor, centred over "
                 f"the magnet. Type AXIS STEP (mm along the pose axes {','.join(axes.pose_axes)}, up to "
                 f"{stage.settings.jog_max:g}; e.g. 'dz -0.1'), end with a move down in dz; an empty line takes "
                 "the zero here; q stops.\n")
    origin = stage.ctrl.position()
    stage.position = origin
    # the steps are from here: a recipe of steps written for another start lands elsewhere by the difference
    stderr.write(f"{prog}: the carriage stands at machine {' '.join(f'{m}{v:g}' for m, v in zip(MACHINE_AXES, origin))}"
                 "\n")
    moved = np.zeros(3)
    up = False  # the last dz jog went up: the stage's backlash then leaves the indenter above where it reads
    while True:
        line = ask_line(stdin, stderr, f"jog [{' '.join(f'{a}{v:+.3f}' for a, v in zip(STAGE_AXES, moved))}]> ")
        if line is None:
            return None
        parts = line.replace("=", " ").split()
        if not parts and up:  # said once: a user who knows the stage has none may take it so
            stderr.write(f"{prog}: the last dz move was up, and backlash leaves the indenter above where the stage "
                         "reads it: come down to contact (e.g. 'dz -0.05'), or press Enter again to take the zero "
                         "here\n")
            up = False
            continue
        if not parts:
            pos = stage.position
            return {m: float(pos[MACHINE_AXES.index(m)]) for m, _, _ in axes.pairs}
        try:
            if len(parts) != 2:
                raise InputError("type AXIS STEP, e.g. dz -0.1")
            try:
                step = float(parts[1])
            except ValueError:
                raise InputError(f"{parts[1]!r} is not a number") from None
            stage.jog(parts[0].lower(), step)
            moved[STAGE_AXES.index(parts[0].lower())] += step
            up = step > 0 if parts[0].lower() == "dz" else up
        except InputError as exc:
            stderr.write(f"{prog}: {exc}\n")
