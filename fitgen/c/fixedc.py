"""What the fixed-point header's template needs beyond the plan: the plan named in words, and the
tables of its AVR code path (firmware_templates/model_fixed.h.j2).

On an AVR with MUL the header keeps every int32 value of the plan in one array and sums each
output's 32x32->64 terms with one assembly routine (fitgen.c.avrasm) that walks a table in flash:
per term the operand's byte offset in the array, the coefficient and the shift. The arithmetic is the
plan's, term for term; only where the numbers live differs.
"""

from __future__ import annotations

from dataclasses import dataclass

from fitgen.c import avrasm
from fitgen.equations.fixedmodel import FixedModel

END = (0xFF, 0xFF)  # the offset that ends a table


@dataclass(frozen=True)
class DotRow:
    data: tuple[int, ...]  # the term's 7 bytes
    text: str  # the term, for a comment


@dataclass(frozen=True)
class AvrPath:
    slot: dict  # int32 value name -> its index in the array
    tables: dict  # output name -> its rows (outputs summed in an int64 accumulator)
    dot_asm: str
    mulsh_asm: str
    divr_asm: str
    uses_mulsh: bool
    uses_divr: bool


def _le(x: int, n: int) -> tuple[int, ...]:
    return tuple((x >> (8 * k)) & 0xFF for k in range(n))


def avr_path(fm: FixedModel) -> AvrPath:
    """The array slots, the dot tables and the assembly of ``fm``'s AVR code path."""
    slot = {}
    for op in fm.ops:
        if op.kind in ("input", "mul", "recip", "out") and op.bits == 32:
            slot[op.name] = len(slot)
    if 4 * len(slot) > 0xFFFE:  # pragma: no cover - 16,000 values
        raise ValueError("too many values for the AVR tables' 16-bit offsets")
    tables: dict = {}
    for op in fm.ops:
        if op.kind == "term" and op.bits == 64:
            name = op.text.split(" += ")[0]
            data = _le(4 * slot[op.args[0]], 2) + _le(op.const, 4) + _le(op.shift, 1)
            tables.setdefault(name, []).append(DotRow(data, op.text.split(" += ")[1]))
    uses_mulsh = any(op.kind == "mul" and op.prod_bits == 64 for op in fm.ops)
    uses_divr = any(op.kind == "recip" and op.prod_bits == 64 for op in fm.ops)
    return AvrPath(slot, tables, avrasm.c_literal(avrasm.dot()), avrasm.c_literal(avrasm.mulsh()),
                   avrasm.c_literal(avrasm.divr()), uses_mulsh, uses_divr)


def plan_line(fm: FixedModel) -> str:
    """The plan in words (the header's comment, the commands' messages)."""
    if fm.mul_bits == 32:
        return "32x32->64 products (for a core with a 32-bit multiply: no --target, or a 32-bit one)"
    kinds: dict = {}
    for o in fm.outputs:
        kind = ("16x16->32 products" if o.acc_bits == 32 else "32x32->64 products, byte-aligned shifts" if o.aligned
                else "32x32->64 products")
        kinds.setdefault(kind, []).append(o.name)
    return ("for a 16-bit multiply (--target uno), each output's error bound within its budget: "
            + "; ".join(f"{', '.join(names)}: {kind}" for kind, names in kinds.items()))
