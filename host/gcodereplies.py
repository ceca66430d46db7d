"""What a G-code controller's lines mean: the faults a Marlin, GRBL (1.1, 0.9, grblHAL, FluidNC) or a firmware
speaking their dialect (Klipper, Smoothieware, RepRapFirmware) reports, as the StageError each is."""

from __future__ import annotations

import re

GRBL_BANNER = re.compile(r"^Grbl(?:HAL)? (\S+)")  # GRBL, FluidNC ("Grbl 3.7 [FluidNC ..."), grblHAL
GRBL_ERRORS = {1: "expected command letter", 2: "bad number format", 3: "invalid $ statement",
               5: "homing is not enabled in the settings", 8: "$ command needs Idle", 9: "G-code locked out "
               "during alarm or jog", 11: "line too long", 15: "jog target exceeds machine travel",
               20: "unsupported or invalid G-code command", 22: "feed rate not set", 33: "invalid motion target"}
GRBL_ALARMS = {1: "hard limit triggered", 2: "soft limit: the target exceeds the machine's travel",
               3: "reset while in motion, position lost", 4: "probe fail", 5: "probe fail",
               6: "homing fail: reset during homing", 8: "homing fail: pull-off did not clear the switch",
               9: "homing fail: no limit switch found", 11: "homing required (grblHAL)",
               12: "a limit switch engaged (grblHAL)"}


LEAVE_ALARM = "run the command again with --home or --unlock to resume"  # GRBL stays in ALARM: the same one fails
CRITICAL_ALARMS = ("1", "2")  # a limit: GRBL halts until a reset (grbl/protocol.c, "Reset to continue")
RESET_FIRST = "GRBL halts after a limit until it is reset: press its reset button or power it off and on, then "


class StageError(RuntimeError):
    """The controller failed: an error or alarm, a halt, silence, a reset, or a position not the commanded one.

    ``lost``: why the machine's position can no longer be trusted ('' when it still can): a resumed
    capture must then not keep the zero (host.stagezero). ``resume``: how to resume, where the same command
    would fail the same way ('' when it would not)."""

    def __init__(self, message: str, lost: str = "", resume: str = ""):
        super().__init__(message)
        self.lost = lost
        self.resume = resume


class NoStatus(StageError):
    """No answer to GRBL's real-time ``?``."""


class NoAnswer(StageError):
    """A command the controller did not answer within its time limit."""


class UnknownCommand(StageError):
    """The controller does not know a command (Marlin's ``echo:Unknown command``)."""


def line_fault(text: str, what: str, name: str, flavor: str | None) -> StageError | None:
    """The StageError a controller's line ``text`` means while it answers ``what`` (``name``: the port; ``flavor``:
    marlin, grbl or None before it is known), or None when the line is harmless."""
    low = text.lower()
    if low.startswith("error:"):
        code = text[6:].strip()
        if flavor == "marlin" or not code.isdigit():
            return StageError(f"{name}: the controller answered {what} with {text!r}")
        meaning = GRBL_ERRORS.get(int(code))
        return StageError(f"{name}: the controller answered {what} with error:{code}"
                          f"{f' ({meaning})' if meaning else ''}")
    if text.startswith("ALARM:"):
        code = text[6:].strip()
        meaning = GRBL_ALARMS.get(int(code)) if code.isdigit() else None
        halts = code in CRITICAL_ALARMS  # GRBL then answers nothing, '?' included, until it is reset
        return StageError(f"{name}: the controller raised ALARM:{code}{f' ({meaning})' if meaning else ''} "
                          f"during {what}; {RESET_FIRST if halts else ''}home it (--home) or unlock it (--unlock), "
                          "then set the zero again", lost=f"the controller raised ALARM:{code}",
                          resume=("reset the controller, then " if halts else "") + LEAVE_ALARM)
    if text.startswith("!! "):  # Klipper's error line (then its ok): the command was refused
        shut = "shutdown" in low
        return StageError(f"{name}: the controller answered {what} with {text!r}"
                          + ("; restart it (FIRMWARE_RESTART), home it and set the zero again" if shut else ""),
                          lost="the controller shut down" if shut else "")
    if text == "!!" or "halted" in low or "kill() called" in low:
        return StageError(f"{name}: the controller halted ({text}) during {what}; reset it, home it and "
                          "set the zero again", lost="the controller halted")
    if re.search(r"home [xyz]+ first", low):  # Marlin built with NO_MOTION_BEFORE_HOMING: the move is ignored
        return StageError(f"{name}: the controller refused {what} until it is homed ({text}); home it "
                          "(--home) if its homing keeps clear of the sensor, then set the zero again",
                          resume="run the command again with --home to resume")
    if low.startswith("echo:unknown command"):
        return UnknownCommand(f"{name}: the controller does not know {what} ({text})")
    if GRBL_BANNER.match(text) or text == "start":
        return StageError(f"{name}: the controller reset itself during {what} (it printed {text!r}); "
                          "its position is lost: set the zero again", lost="the controller reset itself")
    return None
