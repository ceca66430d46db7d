"""AVR assembly of the fixed-point header's 32x32->64 products, for the ATmega328P's MUL instruction.

avr-gcc 5.4 computes ``(int64_t)a * b`` with a library call of about 225 cycles, the header's 64-bit
rounding shift with about 100 more, an int64 addition with 40, and the reciprocals' int64 division with
1,280 (bench/avr_ops.py, in simavr). The routines written here do the same integer
arithmetic in registers (bit for bit: tests/test_avr.py holds them against Python's integers over
their whole operand ranges, and the header built with them against the numpy model):

- ``dot``: ``acc += round(C * p / 2^s)`` (``s`` <= 0: ``C * p * 2^-s``) for every term of a table in
  flash, the accumulator held in registers throughout;
- ``mulsh``: ``*out = round(a * b / 2^s)``, 0 <= s <= 62, for the powers and the v*d products;
- ``divr``: ``*out = round(2^n / den)``, the reciprocals, by long division.

All are naked functions (the avr-gcc calling convention: arguments from r24 downwards, r2-r17 and
r28-r29 kept, r1 left 0); the text is rendered into firmware_templates/model_fixed.h.j2 as C string
literals. A product is the unsigned 4x4-byte product, column by column (each column summed into three
bytes), then corrected for the signs (a < 0 takes b * 2^32 off, b < 0 takes a * 2^32 off). A right
shift by s = 8q + r moves whole bytes and shifts at most 4 bits: for r <= 4, q bytes down then r bits
right; for r >= 5, 8 - r bits left (into a ninth byte) then q + 1 bytes down. The bit below the result
(bit s - 1, the rounding bit) ends in the top of a scratch byte, from where it enters the carry.
"""

from __future__ import annotations

Block = list[str]


def _product(a: list[str], b: list[str], p: list[str], zero: str) -> list[Block]:
    """p (8 bytes) = a * b (4 bytes each, signed); ``zero`` holds 0; r0, r1 are the MUL result."""
    out: list[Block] = [[f"mul {a[0]}, {b[0]}", f"movw {p[0]}, r0", f"clr {p[2]}"]]
    for k in range(1, 7):
        block = [f"clr {p[k + 2]}"] if k + 2 < 8 else []
        for i in range(4):
            j = k - i
            if 0 <= j < 4:
                block += [f"mul {a[i]}, {b[j]}", f"add {p[k]}, r0", f"adc {p[k + 1]}, r1"]
                if k + 2 < 8:
                    block.append(f"adc {p[k + 2]}, {zero}")
        out.append(block)
    for x, y, label in ((a, b, 1), (b, a, 2)):
        out.append([f"sbrs {x[3]}, 7", f"rjmp {label}f", f"sub {p[4]}, {y[0]}", f"sbc {p[5]}, {y[1]}",
                    f"sbc {p[6]}, {y[2]}", f"sbc {p[7]}, {y[3]}", f"{label}:"])
    return out


def _drop(p: list[str], e: str, t: str) -> Block:
    """One byte down: t = p0, p0..p6 = p1..p7, p7 = e, e = e's sign."""
    return ([f"mov {t}, {p[0]}"] + [f"mov {p[m]}, {p[m + 1]}" for m in range(7)]
            + [f"mov {p[7]}, {e}", f"lsl {e}", f"sbc {e}, {e}"])


def _shift(p: list[str], s: str, e: str, t: str) -> list[Block]:
    """p = round(p / 2^s) with the rounding bit left in the carry for s > 0; p * 2^-s and the carry clear
    for s <= 0. ``s`` (signed, |s| <= 62) and ``t`` upper registers (cpi, andi), ``e`` a scratch
    register; all three are changed. Labels 3-8 and 7x."""
    return [
        ["clr " + t, f"tst {s}", "brpl 71f", "rjmp 6f", "71:", "brne 72f", "rjmp 5f"],
        # e: p's sign byte; t = s & 7 = r
        ["72:", f"mov {e}, {p[7]}", f"lsl {e}", f"sbc {e}, {e}", f"mov {t}, {s}", f"andi {t}, 7", f"cpi {t}, 5",
         "brlo 4f", f"subi {s}, -8"],
        # r >= 5: 8 - r bits left (the top into e), and one byte more to come down
        ["31:", f"lsl {p[0]}"] + [f"rol {p[m]}" for m in range(1, 8)]
        + [f"rol {e}", f"inc {t}", f"cpi {t}, 8", "brne 31b", f"andi {s}, 0xF8"],
        # whole bytes down (the last byte out in t), then r <= 4 bits right (the bits out into t)
        ["4:", f"clr {t}"],
        ["41:", f"cpi {s}, 8", "brlo 42f"] + _drop(p, e, t) + [f"subi {s}, 8", "rjmp 41b"],
        ["42:", f"tst {s}", "breq 44f"],
        ["43:", f"asr {p[7]}"] + [f"ror {p[m]}" for m in range(6, -1, -1)] + [f"ror {t}", f"dec {s}", "brne 43b"],
        ["44:", f"lsl {t}", "rjmp 8f"],
        # s < 0: whole bytes up, then bits
        ["6:", f"neg {s}"],
        ["61:", f"cpi {s}, 8", "brlo 62f"] + [f"mov {p[m]}, {p[m - 1]}" for m in range(7, 0, -1)]
        + [f"clr {p[0]}", f"subi {s}, 8", "rjmp 61b"],
        ["62:", f"tst {s}", "breq 5f"],
        ["63:", f"lsl {p[0]}"] + [f"rol {p[m]}" for m in range(1, 8)] + [f"dec {s}", "brne 63b"],
        ["5:", "clc"],
        ["8:"],
    ]


def dot() -> list[Block]:
    """``void dot(int64_t *acc, const int32_t *v, const uint8_t *terms)`` (acc r24:25, v r22:23, terms
    r20:21, in flash): per term, the operand's byte offset in v (2 bytes), the coefficient (4 bytes) and
    the shift (1 byte, signed), little-endian; the offset 0xFFFF ends the table."""
    coef = ["r22", "r23", "r24", "r25"]
    val = ["r18", "r19", "r20", "r21"]
    p = [f"r{10 + m}" for m in range(8)]
    acc = [f"r{2 + m}" for m in range(8)]
    saved = list(range(2, 18)) + [28, 29]
    out: list[Block] = [[f"push r{r}" for r in saved],
                        ["push r24", "push r25", "movw r28, r22", "movw r30, r20", "movw r26, r24"],
                        [f"ld {acc[m]}, X+" for m in range(8)],
                        ["10:", "lpm r26, Z+", "lpm r27, Z+", "cpi r26, 0xFF", "cpc r27, r26", "brne 11f", "rjmp 19f"],
                        ["11:", "add r26, r28", "adc r27, r29"] + [f"ld {val[m]}, X+" for m in range(4)],
                        [f"lpm {coef[m]}, Z+" for m in range(4)] + ["clr r26"]]
    out += _product(coef, val, p, "r26")
    out += [["lpm r27, Z+"]]
    out += _shift(p, "r27", "r18", "r19")
    out += [[f"adc {acc[m]}, {p[m]}" for m in range(8)] + ["rjmp 10b"],
            ["19:", "pop r27", "pop r26"] + [f"st X+, {acc[m]}" for m in range(8)],
            ["clr r1"] + [f"pop r{r}" for r in reversed(saved)] + ["ret"]]
    return out


def mulsh() -> list[Block]:
    """``void mulsh(int32_t a, int32_t b, int8_t s, int32_t *out)`` (a r22-25, b r18-21, s r16, out r14:15):
    *out = round(a * b / 2^s), 0 <= s <= 62, the result within an int32. The bits first (at most 4 right,
    or 3 left into the ninth byte), then the four result bytes picked where they lie."""
    a = ["r22", "r23", "r24", "r25"]
    b = ["r18", "r19", "r20", "r21"]
    p = ["r26", "r27", "r30", "r31", "r2", "r3", "r4", "r5", "r19"]  # p[8]: the ninth byte (the sign)
    s, t = "r18", "r20"  # the shift (then the bytes to skip), the byte below the result
    out: list[Block] = [["push r2", "push r3", "push r4", "push r5", "push r6", "clr r6"]]
    out += _product(a, b, p[:8], "r6")
    # r21 (b's top byte, free now): s, to count the bytes; r16 is the caller's to keep
    out += [["mov r21, r16", f"clr {t}", f"mov {p[8]}, {p[7]}", f"lsl {p[8]}", f"sbc {p[8]}, {p[8]}", f"mov {s}, r21",
             f"andi {s}, 7", f"cpi {s}, 5", "brlo 3f", "subi r21, -8"],
            # r >= 5: 8 - r bits left, and one byte more to skip
            ["31:", f"lsl {p[0]}"] + [f"rol {p[m]}" for m in range(1, 9)] + [f"inc {s}", f"cpi {s}, 8", "brne 31b",
                                                                           f"clr {s}"],
            # r <= 4: r bits right, the bits out into t
            ["3:", f"tst {s}", "breq 4f"],
            ["32:", f"asr {p[8]}"] + [f"ror {p[m]}" for m in range(7, -1, -1)] + [f"ror {t}", f"dec {s}", "brne 32b"],
            # q = the bytes to skip (s >> 3, one more after a left shift); more than 5: whole bytes down first
            ["4:", f"mov {s}, r21", f"lsr {s}", f"lsr {s}", f"lsr {s}"],
            ["41:", f"cpi {s}, 6", "brlo 42f"] + _drop(p[:8], p[8], t) + [f"dec {s}", "rjmp 41b"]]
    # pick bytes q..q+3 into r22..r25 (t = byte q - 1), q = 0..5
    cases = []
    for q in range(6):
        picks = [f"mov r{22 + m}, {p[q + m]}" for m in range(4)]
        cases.append([f"{50 + q}:"] + ([f"mov {t}, {p[q - 1]}"] if q else []) + picks + ["rjmp 59f"])
    out += [["42:", f"cpi {s}, 3", "brsh 43f", f"cpi {s}, 1", "brlo 50f", "breq 51f", "rjmp 52f"],
            ["43:", f"cpi {s}, 4", "brlo 53f", "breq 54f", "rjmp 55f"]]
    out += cases
    out += [["59:", f"lsl {t}", "adc r22, r6", "adc r23, r6", "adc r24, r6", "adc r25, r6", "movw r30, r14",
             "st Z+, r22", "st Z+, r23", "st Z+, r24", "st Z, r25"],
            ["clr r1", "pop r6", "pop r5", "pop r4", "pop r3", "pop r2", "ret"]]
    return out


def divr() -> list[Block]:
    """``void divr(int32_t den, uint32_t hi, uint32_t add, int32_t *out)`` (den r22-25, hi r18-21, add r14-17,
    out r12:13): *out = floor((hi * 2^32 + add + floor(den / 2)) / den) for den > 0, hi < den, add + den / 2
    < 2^32: with (hi, add) = (2^(n - 32), 0) or (0, 2^n), round(2^n / den). Long division of the low word,
    one quotient bit a step, the high word the first remainder; r1 counts the 32 steps down to 0."""
    den = ["r22", "r23", "r24", "r25"]
    lo = ["r26", "r27", "r30", "r31"]  # the dividend's low word, then the quotient
    rem = ["r18", "r19", "r20", "r21"]
    return [["movw r26, r22", "movw r30, r24", "lsr r31", "ror r30", "ror r27", "ror r26",
             "add r26, r14", "adc r27, r15", "adc r30, r16", "adc r31, r17", "clr r1", "inc r1", "swap r1", "lsl r1"],
            ["1:", f"lsl {lo[0]}"] + [f"rol {x}" for x in lo[1:] + rem]
            + [f"cp {rem[0]}, {den[0]}"] + [f"cpc {rem[m]}, {den[m]}" for m in range(1, 4)] + ["brlo 2f"]
            + [f"sub {rem[0]}, {den[0]}"] + [f"sbc {rem[m]}, {den[m]}" for m in range(1, 4)] + [f"inc {lo[0]}"],
            ["2:", "dec r1", "brne 1b", "movw r22, r26", "movw r24, r30", "movw r30, r12", "st Z+, r22", "st Z+, r23",
             "st Z+, r24", "st Z, r25", "ret"]]


def c_literal(blocks: list[Block], indent: str = "        ") -> str:
    """The blocks as C string literals, one block a line (for a basic asm statement)."""
    return "\n".join(indent + '"' + "\\n\\t".join(b) + '\\n\\t"' for b in blocks)
