"""Calibration blobs (format version 1): a fitted model as bytes a firmware loads at run time.

The layout is the contract of docs/protocol.md ("Calibration blob"). ``to_blob``
writes a model; ``from_blob`` reads one back and checks every rule the firmware
checks, so that a blob this module accepts is one the firmware accepts (given a
build of the same precision and counts).
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass

import numpy as np

from fitgen.base.errors import InputError
from fitgen.equations.model import MAX_INPUTS, Equation, Model
from fitgen.physics.pose import POSE_NAMES
from fitgen.equations.terms import DISPLACEMENTS, EXPONENTS, Term

MAGIC = b"TMCB"
FORMAT_VERSION = 1
PRECISION_CODES = {"double": 0, "float": 1}
REAL_DTYPES = {"double": "<f8", "float": "<f4"}
FLAG_FMA = 0x01
HEADER_SIZE = 60  # magic .. n_terms_total; the domain follows
TRAILER_SIZE = 4  # crc
SENSOR_ID_SIZE = 16
MAX_OUTPUTS = len(POSE_NAMES)
MAX_TERMS = 0xFFFF
_HEADER = struct.Struct("<4sHBB32s16sBBH")
_OUTPUT = struct.Struct("<BBH")  # pose, d_slot, n_terms (the intercept follows)
# largest |intercept| + sum |coefficient * term| in the domain: as fitgen.c.codegen refuses for its headers
_LIMIT = {"double": 1e15, "float": 1e30}


@dataclass(frozen=True)
class BlobInfo:
    """What a blob holds: the model as stored (float blobs: rounded) and its header fields."""

    model: Model
    precision: str
    fma: bool
    model_hash: str  # hex of the stored hash: Model.sha256 of the model the blob was made from
    sensor_id: str
    format_version: int

    @property
    def n_terms(self) -> int:
        return sum(len(e.terms) for e in self.model.equations)


def real_size(precision: str) -> int:
    return np.dtype(REAL_DTYPES[precision]).itemsize


def blob_size(n_inputs: int, n_outputs: int, n_terms_total: int, precision: str) -> int:
    """Bytes of a blob with these counts."""
    r = real_size(precision)
    return HEADER_SIZE + 2 * n_inputs * r + n_outputs * (_OUTPUT.size + r) + n_terms_total * (4 + r) + TRAILER_SIZE


def size_from_header(header: bytes) -> int:
    """A blob's full size from its first HEADER_SIZE bytes (InputError if they are not a v1 header)."""
    if len(header) < HEADER_SIZE:
        raise InputError(f"calibration blob: {len(header)} bytes is shorter than its {HEADER_SIZE}-byte header")
    magic, version, prec, _flags, _h, _s, n_in, n_out, total = _HEADER.unpack_from(header)
    precision = _check_header(magic, version, prec)
    return blob_size(n_in, n_out, total, precision)


def rounded_model(model: Model, precision: str = "float") -> Model:
    """The model as a blob of this precision stores it.

    float: the domain rounded outward (fitgen.c.codegen.float_domain), intercepts and
    coefficients rounded to the nearest float (as the C literals of a float header).
    """
    if precision not in PRECISION_CODES:
        raise InputError(f"precision must be one of {', '.join(PRECISION_CODES)}, got {precision!r}")
    if precision == "double":
        return model
    from fitgen.c.codegen import float_domain

    def f32(x: float, what: str) -> float:
        y = np.float32(x) if abs(x) <= float(np.finfo(np.float32).max) else np.float32(np.inf)
        if not np.isfinite(y):
            raise InputError(f"{what} {x!r} does not fit in a float")
        return float(y)

    lo, hi = float_domain(model)
    eqs = tuple(Equation(e.name, f32(e.intercept, f"output {e.name}: intercept"), e.terms,
                         tuple(f32(c, f"output {e.name}: coefficient") for c in e.coefficients))
                for e in model.equations)
    return Model(lo, hi, eqs, model.input_units, dict(model.fit_info))


def check_sensor_id(sensor_id: str) -> str:
    """``sensor_id`` as a blob carries it (printable ASCII, at most 16 characters); InputError otherwise."""
    if not isinstance(sensor_id, str) or not all(" " <= ch <= "~" for ch in sensor_id):
        raise InputError(f"sensor id {sensor_id!r}: printable ASCII characters only")
    if len(sensor_id) > SENSOR_ID_SIZE:
        raise InputError(f"sensor id {sensor_id!r} is longer than {SENSOR_ID_SIZE} characters")
    return sensor_id


def model_sensor_id(model: Model, fallback: str = "paper", also=None) -> str:
    """The sensor id a blob of ``model`` carries unless told: the name of the sensor its held-out figures are
    for (a unit file's, as identify names it: ``-o unit-042.toml`` gives ``unit-042``), where it is one a blob
    can carry (and ``also(name)``, a firmware's own check, raises no InputError); ``fallback`` for a model that
    names none. InputError for a name no blob can carry: the drawing's id in its place would call a unit's
    calibration the drawing's."""
    name = (model.fit_info.get("held_out") or {}).get("sensor")
    if not isinstance(name, str) or not name:
        return fallback
    try:
        check_sensor_id(name)
        if also is not None:
            also(name)
    except InputError as exc:
        raise InputError(f"the model's sensor, {name!r}, cannot be the calibration's sensor id ({exc}): give one "
                         "with --sensor-id") from None
    return name


def blob_refusal(model: Model) -> str:
    """Why no calibration blob holds ``model``, whatever the firmware's precision; '' when one can."""
    built_in = "build it into the firmware instead (`fitgen codegen`, `tactile-hil emulate --model`)"
    if model.refine is not None:
        return f"the calibration blob format has no refinement: fit without --refine to flash the model, or {built_in}"
    harm = next((t for e in model.equations for t in e.terms if t.harm), None)
    if harm is not None:
        return (f"the calibration blob format has no harmonic terms ({harm.text}), which the default --family auto "
                f"keeps where they validate better: fit with --family all, no-roots or integer to flash the model, "
                f"or {built_in}")
    if model.n_inputs > MAX_INPUTS:
        return f"the model takes {model.n_inputs} inputs; a calibration blob holds at most {MAX_INPUTS}"
    total = sum(len(e.terms) for e in model.equations)
    if total > MAX_TERMS:
        return f"the model has {total} terms; a calibration blob holds at most {MAX_TERMS}"
    return ""


def to_blob(model: Model, precision: str = "float", sensor_id: str = "paper", fma: bool = False) -> bytes:
    """The calibration blob (format version 1) of ``model`` for a firmware of this precision."""
    if precision not in PRECISION_CODES:
        raise InputError(f"precision must be one of {', '.join(PRECISION_CODES)}, got {precision!r}")
    if refused := blob_refusal(model):
        raise InputError(refused)
    check_sensor_id(sensor_id)
    total = sum(len(e.terms) for e in model.equations)
    from fitgen.c.codegen import term_magnitudes

    for name, mag in term_magnitudes(model).items():
        if not mag <= _LIMIT[precision]:
            raise InputError(f"output {name}: its terms reach {mag:.3g} in the input domain, over the {precision} "
                             f"limit {_LIMIT[precision]:g} (absurd coefficients, or a sum that could overflow)")
    stored = rounded_model(model, precision)
    if refused := magnitude_refusal(stored.input_min, stored.input_max, stored.equations, precision):
        raise InputError(refused)  # the firmware would refuse the blob: past the limit once stored, or on the way
    real = np.dtype(REAL_DTYPES[precision])

    def reals(values) -> bytes:
        arr = np.asarray(values, dtype=float)
        if not np.all(np.isfinite(arr)):
            raise InputError("the model holds a non-finite number; no calibration blob made")
        return arr.astype(real).tobytes()

    out = bytearray(_HEADER.pack(MAGIC, FORMAT_VERSION, PRECISION_CODES[precision], FLAG_FMA if fma else 0,
                                 bytes.fromhex(model.sha256), sensor_id.encode("ascii"), model.n_inputs,
                                 len(model.equations), total))
    out += reals(stored.input_min) + reals(stored.input_max)
    for eq in stored.equations:
        d_slot = DISPLACEMENTS.index(eq.name) + 1 if eq.name in DISPLACEMENTS else 0
        out += _OUTPUT.pack(POSE_NAMES.index(eq.name), d_slot, len(eq.terms)) + reals([eq.intercept])
        for t in eq.terms:
            mult = DISPLACEMENTS.index(t.mult) + 1 if t.mult else 0
            out += struct.pack("<bBBB", t.element - 1, EXPONENTS.index(t.exponent) if t.element else 0, mult, 0)
        out += reals(eq.coefficients)
    out += struct.pack("<I", zlib.crc32(out) & 0xFFFFFFFF)
    assert len(out) == blob_size(model.n_inputs, len(model.equations), total, precision)
    return bytes(out)


def magnitude_refusal(lo, hi, equations, precision: str) -> str:
    """Why the firmware refuses these outputs' magnitudes (cal_parse in firmware/cal.c.j2); '' when it does not.

    term_magnitudes' bound of |intercept| + sum |coefficient * term| over the domain, within _LIMIT[precision],
    and every power, power times a d, term and partial sum on the way too (so that no number the firmware forms
    overflows; a root's bound is a power of two). cal_parse's operations in its order, in the blob's precision
    (numpy float32 or float64 scalars: IEEE-754, rounded to nearest), so that both refuse the same blobs."""
    real = np.float32 if precision == "float" else np.float64
    one, limit = real(1), real(_LIMIT[precision])

    def mul(a, b):  # a * b (a, b >= 0), None over the limit: tested by a division before it is formed
        if a is None or b is None or b > one and a > limit / b:
            return None
        return a * b if a * b <= limit else None

    def power(k: int, a, b):  # bound of |v|^p over [a, b] for exponent code k
        if k < 4:
            m = v = max(abs(a), abs(b))
            for _ in range(k):
                m = mul(m, v)
            return m if m is not None and m <= limit else None
        m = one
        if k < 8:
            for _ in range(k - 3):
                if a < one and m > limit * a:
                    return None
                m = m / a
            return m if m <= limit else None
        h, step = b, real(2 ** (k - 6))  # k - 6: the root's n; step 2^n
        while h > one:
            h, m = h / step, m + m
            if not m <= limit:
                return None
        return m

    bound_d: dict = {}
    over = f"over the {precision} limit {float(limit):g} in the input domain"
    for eq in equations:
        total = abs(real(eq.intercept))
        if not total <= limit:
            return f"output {eq.name}: the intercept {float(total):.3g} is {over}"
        for t, c in zip(eq.terms, eq.coefficients):
            m = one
            if t.element:
                a, b = real(lo[t.element - 1]), real(hi[t.element - 1])
                k = EXPONENTS.index(t.exponent)
                if (m := power(k, a, b)) is None:
                    end = f"input_min {float(a)!r}" if 4 <= k < 8 else f"input_max {float(b)!r}" if k >= 8 else \
                        f"bounds {float(a)!r}, {float(b)!r}"
                    return f"output {eq.name}: {t.text} reaches {over} (its {end})"
            if t.mult and (m := mul(m, bound_d[t.mult])) is None:
                return f"output {eq.name}: {t.text} reaches {over} ({t.mult} up to {float(bound_d[t.mult]):.3g})"
            if (m := mul(abs(real(c)), m)) is None or not total + m <= limit:
                what = "its terms reach" if m is not None else f"the coefficient {c:.3g} times {t.text} reaches"
                return f"output {eq.name}: {what} {over} (absurd coefficients, or a sum that could overflow)"
            total = total + m
        if eq.name in DISPLACEMENTS:
            bound_d[eq.name] = total
    return ""


def _fail(message: str):
    raise InputError(f"calibration blob: {message}")


def _check_header(magic: bytes, version: int, prec: int) -> str:
    if magic != MAGIC:
        _fail(f"bad magic {magic!r} (expected {MAGIC!r})")
    if version != FORMAT_VERSION:
        _fail(f"format version {version} is not supported (this fitgen reads {FORMAT_VERSION})")
    for name, code in PRECISION_CODES.items():
        if code == prec:
            return name
    _fail(f"unknown precision code {prec} (0 double, 1 float)")


def from_blob(data: bytes) -> BlobInfo:
    """The model and header of a calibration blob; InputError naming the first rule it breaks."""
    data = bytes(data)
    if len(data) < HEADER_SIZE + TRAILER_SIZE:
        _fail(f"{len(data)} bytes is too short (a header and a CRC alone are {HEADER_SIZE + TRAILER_SIZE})")
    magic, version, prec, flags, mhash, sid, n_in, n_out, total = _HEADER.unpack_from(data)
    precision = _check_header(magic, version, prec)
    real = np.dtype(REAL_DTYPES[precision])
    r = real.itemsize
    if not 1 <= n_in <= MAX_INPUTS:
        _fail(f"n_inputs {n_in} is out of range 1..{MAX_INPUTS}")
    if not 1 <= n_out <= MAX_OUTPUTS:
        _fail(f"n_outputs {n_out} is out of range 1..{MAX_OUTPUTS}")

    # the sizes first: walk the outputs' term counts, never reading past the end
    pos = HEADER_SIZE + 2 * n_in * r
    counts = []
    for j in range(n_out):
        if pos + _OUTPUT.size > len(data) - TRAILER_SIZE:
            _fail(f"{len(data)} bytes is too short for the {n_out} outputs its header announces")
        counts.append(_OUTPUT.unpack_from(data, pos)[2])
        pos += _OUTPUT.size + r + counts[-1] * (4 + r)
    if sum(counts) != total:
        _fail(f"the outputs' term counts sum to {sum(counts)}, the header says {total}")
    expected = pos + TRAILER_SIZE
    if expected != len(data):
        _fail(f"wrong size: {len(data)} bytes, its header and term counts make {expected}")
    (stored_crc,) = struct.unpack_from("<I", data, len(data) - TRAILER_SIZE)
    crc = zlib.crc32(data[:-TRAILER_SIZE]) & 0xFFFFFFFF
    if crc != stored_crc:
        _fail(f"CRC mismatch: stored {stored_crc:08x}, computed {crc:08x}")

    # then every field
    if flags & ~FLAG_FMA:
        _fail(f"unknown flags 0x{flags:02x} (only bit 0, fma, is defined)")
    nul = sid.find(b"\0")
    text, pad = (sid, b"") if nul < 0 else (sid[:nul], sid[nul:])
    if pad.strip(b"\0") or not all(0x20 <= b < 0x7F for b in text):
        _fail(f"sensor id {sid!r} is not printable ASCII padded with NULs")

    def reals(offset: int, n: int, what: str) -> np.ndarray:
        arr = np.frombuffer(data, dtype=real, count=n, offset=offset).astype(float)
        if not np.all(np.isfinite(arr)):
            _fail(f"{what} holds a non-finite number")
        return arr

    lo = reals(HEADER_SIZE, n_in, "input_min")
    hi = reals(HEADER_SIZE + n_in * r, n_in, "input_max")
    if np.any(lo > hi):
        _fail(f"input v{int(np.argmax(lo > hi)) + 1} has input_min > input_max")
    pos = HEADER_SIZE + 2 * n_in * r
    eqs: list[Equation] = []
    feeds_d: set[str] = set()  # displacement outputs so far whose d_slot is set
    last_pose = -1
    for j in range(n_out):
        pose, d_slot, n_terms = _OUTPUT.unpack_from(data, pos)
        if pose >= len(POSE_NAMES):
            _fail(f"output {j}: unknown pose code {pose} (0..{len(POSE_NAMES) - 1})")
        if pose <= last_pose:
            _fail(f"output {j}: poses must be strictly increasing ({POSE_NAMES[pose]} after {POSE_NAMES[last_pose]})")
        last_pose = pose
        name = POSE_NAMES[pose]
        slot = DISPLACEMENTS.index(name) + 1 if name in DISPLACEMENTS else 0
        if d_slot not in (0, slot):
            _fail(f"output {name}: d_slot {d_slot}, expected 0{f' or {slot}' if slot else ''}")
        (intercept,) = reals(pos + _OUTPUT.size, 1, f"output {name}: the intercept")
        pos += _OUTPUT.size + r
        terms = []
        for i in range(n_terms):
            element, exp, mult, reserved = struct.unpack_from("<bBBB", data, pos + 4 * i)
            where = f"output {name}: term {i}"
            if reserved:
                _fail(f"{where}: reserved byte is {reserved}, not 0")
            if exp >= len(EXPONENTS):
                _fail(f"{where}: unknown exponent code {exp} (0..{len(EXPONENTS) - 1})")
            if mult > len(DISPLACEMENTS):
                _fail(f"{where}: unknown multiplier code {mult} (0 none, 1 dx, 2 dy, 3 dz)")
            if element == -1:
                if not mult or exp:
                    _fail(f"{where}: a bare displacement term needs a multiplier and exponent code 0")
                term = Term(mult=DISPLACEMENTS[mult - 1])
            elif 0 <= element < n_in:
                if mult and exp:
                    _fail(f"{where}: a displacement product takes v{element + 1} to the power 1 only")
                term = Term(element + 1, EXPONENTS[exp], DISPLACEMENTS[mult - 1] if mult else "")
            else:
                _fail(f"{where}: element {element} is out of range (-1, or 0..{n_in - 1})")
            if term.mult and term.mult not in feeds_d:
                _fail(f"{where} ({term.text}): {term.mult} is not an output before {name} that feeds the d-terms")
            if term.needs_positive and not lo[term.element - 1] > 0:
                _fail(f"{where} ({term.text}): needs input_min of v{term.element} > 0, it is {lo[term.element - 1]!r}")
            terms.append(term)
        if len(set(terms)) != len(terms):
            _fail(f"output {name} lists a term twice")
        pos += 4 * n_terms
        coefs = reals(pos, n_terms, f"output {name}: the coefficients")
        pos += n_terms * r
        eqs.append(Equation(name, float(intercept), tuple(terms), tuple(float(c) for c in coefs)))
        if d_slot:
            feeds_d.add(name)
    if refused := magnitude_refusal(lo, hi, eqs, precision):
        _fail(refused)
    try:
        model = Model(lo, hi, tuple(eqs), fit_info={"source": "calibration blob"})
    except InputError as exc:  # every rule is checked above; this is a safety net
        _fail(str(exc))
    return BlobInfo(model, precision, bool(flags & FLAG_FMA), mhash.hex(), text.decode("ascii"), version)
