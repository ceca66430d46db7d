"""The cores a generated header can be for, and what each lets a header use: one table.

``fitgen codegen --target NAME`` checks a header against its row; without a target a header
is for any core with an IEEE double (a double header checks that itself when compiled).
"""

from __future__ import annotations

from dataclasses import dataclass

from fitgen.base.errors import InputError


@dataclass(frozen=True)
class Target:
    name: str
    core: str  # what the core is, for messages and docs
    precisions: tuple[str, ...]  # the header precisions it may run
    fpu: str  # "none", "single" (float in hardware, double in software) or "double"
    double_bits: int  # sizeof(double) * 8 under the target's compiler
    ram: int | None  # bytes; None: an operating system's memory, no fixed budget
    flash: int | None  # bytes of program memory
    progmem: bool  # const tables must be placed in flash explicitly (PROGMEM) to stay out of RAM
    mul_bits: int  # the core's natural multiply: 16 (8-bit AVR: MUL makes 16x16->32 cheap), 32 (32x32->64)
    why: str = ""  # why a precision is missing, for the refusal
    int_bits: int = 32  # sizeof(int) * 8: the generated C's status is an int with one bit per input


TARGETS = {t.name: t for t in (
    Target("uno", "ATmega328P (Arduino Uno), 8-bit AVR at 16 MHz", ("float", "fixed"), "none", 32,
           2048, 32768, True, 16,
           "avr-gcc's double is 32 bits (DBL_MANT_DIG 24), so a double header cannot run there", int_bits=16),
    Target("microbit", "nRF51822 (BBC micro:bit), Cortex-M0 at 16 MHz", ("fixed",), "none", 64, 16384, 262144,
           False, 32, "the Cortex-M0 has no FPU: the reference firmware runs fixed point there (hil/firmware.py)"),
    Target("mps2", "MPS2-AN386, Cortex-M4F", ("double", "float", "fixed"), "single", 64, 4 << 20, 4 << 20, False, 32),
    Target("pi", "Raspberry Pi (ARMv7/ARMv8 Linux, VFP)", ("double", "float"), "double", 64, None, None, False, 32,
           "the Pi build (host/pi.py) computes in float or double"),
)}

# the cores whose cycles per estimate are counted in an emulator (fitgen.c.avr: simavr), for fitgen tradeoff --core
CYCLE_TARGETS = ("uno",)


def get_target(name: str | None) -> Target | None:
    """The row of ``name``; None for None (no target named)."""
    if name is None:
        return None
    if name not in TARGETS:
        raise InputError(f"target must be one of {', '.join(TARGETS)}, got {name!r}")
    return TARGETS[name]


def check_model(t: Target | None, model) -> None:
    """InputError (one line) when ``model`` cannot run on target ``t`` (None: any core with a 32-bit int) in any
    precision: predict refuses what codegen would, so no estimate is printed for C that is never written."""
    from fitgen.equations.model import MAX_INPUTS

    most = MAX_INPUTS if t is None or t.int_bits >= 32 else t.int_bits - 1  # a positive int: its sign bit stays 0
    if model.n_inputs > most:
        where = f"target {t.name}'s {t.int_bits}-bit int" if t is not None and t.int_bits < 32 else "a C int"
        raise InputError(f"the model has {model.n_inputs} inputs; the generated C's status (one bit per input, in "
                         f"{where}) holds at most {most}")
    if t is not None and t.progmem and model.refine is not None:
        raise InputError(f"target {t.name}: a refinement's forward model and solve do not fit the {t.core} "
                         "(its tables in RAM, its code past the flash): fit without --refine")


def default_precision(target: str | None, fitted: str) -> str:
    """The precision codegen writes when none is given: double, unless the target cannot run it; then the
    precision the model was fitted for (``fitted``) if the target runs that, else the target's first."""
    t = get_target(target)
    if t is None or "double" in t.precisions:
        return "double"
    return fitted if fitted in t.precisions else t.precisions[0]


def header_precision(target: str | None, given: str | None, model) -> str:
    """``given`` (--precision), else :func:`default_precision` for ``model``; InputError when that default is
    fixed point, the target's only arithmetic, and the model has what fixed point cannot run (said as the
    target's, not as a precision the user never asked for)."""
    from fitgen.equations.fixedpoint import fixed_refusal
    from fitgen.fitting.holdout import device_precision

    if given:
        return given
    chosen = default_precision(target, device_precision(model))
    if chosen == "fixed" and (why := fixed_refusal(model)):
        t = get_target(target)
        raise InputError(f"target {t.name} ({t.core}) runs fixed point only, and {why}")
    return chosen


def check_precision(target: str | None, precision: str) -> Target | None:
    """The target's row, or an InputError (one line) when it may not run ``precision``."""
    t = get_target(target)
    if t is not None and precision not in t.precisions:
        raise InputError(f"target {t.name} ({t.core}) takes --precision {' or '.join(t.precisions)}, not "
                         f"{precision}: {t.why}")
    return t
