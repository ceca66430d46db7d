"""Calibration blobs whose terms can overflow (docs/protocol.md, "Calibration blob"): a whole blob, a sound CRC,
every number finite, and yet a coefficient, a domain end near 0 under a negative power or a domain end far from 0
under a high power takes an output past the precision's limit (fitgen.c.calblob._LIMIT, which to_blob holds a
model to). from_blob refuses each with its reason, the host build of the firmware (cal_parse) answers CAL_INVALID
and keeps the calibration it had, and at the limit's edge both accept the same blob and refuse the next one."""

from __future__ import annotations

import struct
import subprocess

import numpy as np
import pytest

from fitgen.base.errors import InputError
from fitgen.c.calblob import HEADER_SIZE, from_blob, to_blob
from fitgen.equations.model import Equation, Model
from fitgen.equations.terms import parse_term
from hil.firmware import build_firmware, render_firmware
from host import protocol as P
from host.protocol import ErrorCode as E
from host.protocol import MsgType as T

from conftest import require_tool
from test_calblob import reseal
from test_firmware_build import Link, load_blob

REAL = {"float": "<f", "double": "<d"}
TINY = {"float": 1e-45, "double": 5e-324}  # the least subnormal
SMALL = {"float": 1e-12, "double": 1e-80}  # a normal number: its 1/v^3 is past the limit
HUGE = {"float": 3e38, "double": 1.7e308}  # near the type's largest
FAR = {"float": 1e30, "double": 1e300}


def model() -> Model:
    """2 inputs: v1 in [0.5, 2] under a negative power and a root, v2 in [-1, 1] under a 4th power and times dx."""
    eqs = (Equation("dx", 0.25, (parse_term("v1^-3"), parse_term("v2^4"), parse_term("v1^1/3")), (1.5, -2.0, 0.5)),
           Equation("thx", -1.0, (parse_term("dx"), parse_term("v2*dx")), (0.5, 3.0)))
    return Model(np.array([0.5, -1.0]), np.array([2.0, 1.0]), eqs)


def offsets(precision: str) -> dict:
    """Where model()'s blob holds v1's minimum, v2's maximum and dx's coefficients of v1^-3 and v2^4."""
    r = struct.calcsize(REAL[precision])
    coefs = HEADER_SIZE + 4 * r + 4 + r + 3 * 4
    return {"v1_min": HEADER_SIZE, "v2_max": HEADER_SIZE + 3 * r, "c_v1^-3": coefs, "c_v2^4": coefs + r}


def patched(blob: bytes, precision: str, field: str, value: float) -> bytes:
    out = bytearray(blob)
    struct.pack_into(REAL[precision], out, offsets(precision)[field], value)
    return reseal(out)


def crafted(precision: str) -> dict:
    """The four blobs of the defect (fitgen 0.1.0 took them), by name: blob, the words of from_blob's refusal."""
    blob = to_blob(model(), precision)
    return {"huge coefficient": (patched(blob, precision, "c_v2^4", HUGE[precision]), "the coefficient .* v2\\^4"),
            "tiny minimum": (patched(blob, precision, "v1_min", TINY[precision]), "v1\\^-3 reaches .*input_min"),
            "small minimum": (patched(blob, precision, "v1_min", SMALL[precision]), "v1\\^-3 reaches .*input_min"),
            "huge maximum": (patched(blob, precision, "v2_max", FAR[precision]), "v2\\^4 reaches .*bounds")}


def edge(precision: str, field: str, up: bool) -> tuple[bytes, bytes]:
    """The last blob from_blob takes as ``field`` grows (up) or shrinks toward 0 in magnitude, and the first it
    refuses: the field's two neighbouring reals (bisected on their bits, which order positive reals)."""
    blob = to_blob(model(), precision)
    bits, real = ("<I", "<f") if precision == "float" else ("<Q", "<d")

    start = struct.unpack_from(real, blob, offsets(precision)[field])[0]

    def at(n: int) -> bytes:  # the n-th positive real, with the field's sign
        return patched(blob, precision, field, np.copysign(struct.unpack(real, struct.pack(bits, n))[0], start))

    def takes(n: int) -> bool:
        try:
            from_blob(at(n))
        except InputError:
            return False
        return True

    good = struct.unpack(bits, struct.pack(real, abs(start)))[0]
    bad = struct.unpack(bits, struct.pack(real, HUGE[precision] if up else TINY[precision]))[0]
    assert takes(good) and not takes(bad)
    while abs(bad - good) > 1:
        mid = (good + bad) // 2
        good, bad = (mid, bad) if takes(mid) else (good, mid)
    return at(good), at(bad)


@pytest.mark.parametrize("precision", ["float", "double"])
def test_from_blob_refuses_terms_past_the_limit(precision):
    for name, (blob, words) in crafted(precision).items():
        with pytest.raises(InputError, match=words) as exc:
            from_blob(blob)
        assert "\n" not in str(exc.value) and f"over the {precision} limit" in str(exc.value), name
    # the edges: one real apart, on each side of the limit
    for field, up in (("c_v2^4", True), ("c_v1^-3", True), ("v1_min", False)):
        good, bad = edge(precision, field, up)
        assert from_blob(good).precision == precision
        with pytest.raises(InputError, match="over the"):
            from_blob(bad)


def test_to_blob_refuses_what_the_firmware_would():
    """A model within term_magnitudes' limit whose v1^-4 alone is past it (1e32): in a float build, coefficient 0
    times an infinite power would be NaN."""
    m = Model(np.array([1e-8, -1.0]), np.array([2.0, 1.0]),
              (Equation("dx", 0.0, (parse_term("v1^-4"), parse_term("v2^1")), (0.0, 1.0)),))
    for precision in ("float", "double"):
        with pytest.raises(InputError, match=f"v1\\^-4 reaches over the {precision} limit"):
            to_blob(m, precision)
    from fitgen.c.calblob import magnitude_refusal

    assert magnitude_refusal(m.input_min, m.input_max, m.equations, "float").startswith("output dx: v1^-4")
    assert magnitude_refusal(model().input_min, model().input_max, model().equations, "float") == ""


@pytest.fixture(scope="module", params=["float", "double"])
def host_build(request, tmp_path_factory):
    """The host build of the firmware for model() (in the blob's precision)."""
    require_tool("gcc")
    folder = tmp_path_factory.mktemp(f"fw-magnitudes-{request.param}")
    render_firmware(model(), folder, precision=request.param, style="table", port="posix")
    return request.param, build_firmware(folder, "posix")


def commit(link: Link, blob: bytes, seq: int) -> int:
    """CAL_COMMIT's error code for a whole, well-sent blob."""
    link.ok(T.CAL_BEGIN, seq, P.pack_cal_begin(len(blob), P.crc32(blob)))
    for off in range(0, len(blob), P.CAL_DATA_MAX):
        link.ok(T.CAL_DATA, seq, P.pack_cal_data(off, blob[off:off + P.CAL_DATA_MAX]))
    return link.error(T.CAL_COMMIT, seq)


def test_firmware_refuses_terms_past_the_limit(host_build):
    precision, fw = host_build
    other = Model(model().input_min, model().input_max,
                  tuple(Equation(e.name, e.intercept + 1, e.terms, e.coefficients) for e in model().equations))
    loaded = to_blob(other, precision, sensor_id="loaded")
    proc = subprocess.Popen([str(fw)], stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    try:
        link = Link(proc.stdout.fileno(), proc.stdin.fileno())
        assert load_blob(link, loaded) == bytes.fromhex(other.sha256)
        x = P.pack_eval(np.array([[0.7, 0.3], [3.0, -2.0]]), P.real_dtype(precision))
        before = link.ok(T.EVAL, 2, x)
        for name, (blob, _) in crafted(precision).items():
            assert commit(link, blob, 3) == E.CAL_INVALID, name
            info = P.unpack_info(link.ok(T.INFO, 4))
            assert info.cal_source == 1 and info.sensor_id == "loaded" and info.model_hash == other.sha256, name
            assert link.ok(T.CAL_READ, 5, P.pack_cal_read(0, 256)) == loaded and link.ok(T.EVAL, 6, x) == before
        # at the limit's edge the firmware takes the blob from_blob takes and refuses the next real's
        for field, up in (("c_v2^4", True), ("c_v1^-3", True), ("v1_min", False)):
            good, bad = edge(precision, field, up)
            assert commit(link, bad, 7) == E.CAL_INVALID, field
            assert load_blob(link, good, 8) == bytes.fromhex(model().sha256), field
            _, out = P.unpack_eval_reply(link.ok(T.EVAL, 9, x), 2, P.real_dtype(precision))
            assert np.all(np.isfinite(out)), field
    finally:
        proc.kill()
        proc.wait()
        proc.stdin.close()
        proc.stdout.close()
