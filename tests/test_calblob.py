"""Calibration blobs (docs/protocol.md, format version 1): round trips and refusals."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest

from fitgen.c.calblob import (HEADER_SIZE, blob_size, from_blob, rounded_model, size_from_header, to_blob)
from fitgen.base.errors import InputError
from fitgen.equations.model import Equation, Model
from fitgen.equations.terms import parse_term


@pytest.fixture(scope="module")
def paper_model():
    from fitgen.fitting.fit import fit_model
    from fitgen.physics.sensor import load_sensor
    from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate

    return fit_model(simulate(load_sensor("paper"), grid_poses(PAPER_GRIDS["paper-sim"])))


def inputs(model, n=3000, seed=0):
    rng = np.random.default_rng(seed)
    lo, hi = model.input_min, model.input_max
    width = hi - lo
    return np.vstack([lo + width * rng.random((n, model.n_inputs)),
                      lo - width * rng.random((50, model.n_inputs)),  # clamped
                      hi + width * rng.random((50, model.n_inputs)),
                      np.vstack([lo, hi])])


def test_double_round_trip_is_exact(paper_model):
    blob = to_blob(paper_model, "double", sensor_id="rig-7", fma=True)
    info = from_blob(blob)
    assert info.precision == "double" and info.fma and info.sensor_id == "rig-7" and info.format_version == 1
    assert info.model_hash == paper_model.sha256
    assert info.model.output_names == paper_model.output_names
    for a, b in zip(info.model.equations, paper_model.equations):
        assert a.terms == b.terms and a.coefficients == b.coefficients and a.intercept == b.intercept
    x = inputs(paper_model)
    out, st = info.model.predict(x, with_status=True)
    ref, ref_st = paper_model.predict(x, with_status=True)
    assert np.array_equal(out, ref) and np.array_equal(st, ref_st)
    assert len(blob) == size_from_header(blob[:HEADER_SIZE])
    assert to_blob(paper_model, "double", sensor_id="rig-7", fma=True) == blob  # deterministic


def test_float_round_trip_is_the_rounded_model(paper_model):
    from fitgen.c.codegen import float_domain

    blob = to_blob(paper_model, "float")
    info = from_blob(blob)
    assert info.precision == "float" and not info.fma and info.sensor_id == "paper"
    assert info.model_hash == paper_model.sha256 != info.model.sha256
    lo, hi = float_domain(paper_model)
    assert np.array_equal(info.model.input_min, lo) and np.array_equal(info.model.input_max, hi)
    for e in info.model.equations:
        assert all(float(np.float32(c)) == c for c in e.coefficients + (e.intercept,))
    x = inputs(paper_model)
    assert np.array_equal(info.model.predict(x), rounded_model(paper_model, "float").predict(x))
    n_terms = sum(len(e.terms) for e in paper_model.equations)
    assert len(blob) == blob_size(8, 5, n_terms, "float") == size_from_header(blob)
    assert len(to_blob(paper_model, "double")) > len(blob)


def test_every_byte_corruption_is_refused(paper_model):
    blob = to_blob(paper_model, "float")
    for i in range(len(blob)):
        for flip in (0x01, 0x80):
            bad = bytearray(blob)
            bad[i] ^= flip
            with pytest.raises(InputError) as exc:
                from_blob(bytes(bad))
            assert "\n" not in str(exc.value)


def test_truncations_and_extensions_are_refused(paper_model):
    blob = to_blob(paper_model, "double")
    for n in list(range(0, 80)) + list(range(len(blob) - 40, len(blob))):
        with pytest.raises(InputError):
            from_blob(blob[:n])
    with pytest.raises(InputError, match="wrong size"):
        from_blob(blob + b"\0")


def reseal(blob: bytearray) -> bytes:
    """The blob with its trailing CRC recomputed: a well-formed container around a bad field."""
    blob[-4:] = struct.pack("<I", zlib.crc32(bytes(blob[:-4])))
    return bytes(blob)


def small_model(lo=0.5):
    eqs = (Equation("dx", 0.25, (parse_term("v1^-1"), parse_term("v2^2")), (1.5, -2.0)),
           Equation("thx", -1.0, (parse_term("dx"), parse_term("v2*dx")), (0.5, 3.0)))
    return Model(np.array([lo, -1.0]), np.array([2.0, 1.0]), eqs)


# offsets in a double blob of small_model(): domain at 60 (4 reals), outputs from 92
DOM, OUT0 = 60, 92
TERMS0 = OUT0 + 4 + 8  # dx's first term
OUT1 = TERMS0 + 2 * 4 + 2 * 8
TERMS1 = OUT1 + 4 + 8


@pytest.mark.parametrize("offset, value, words", [
    (0, b"XMCB", "bad magic"),
    (4, struct.pack("<H", 2), "format version 2"),
    (6, b"\x02", "precision code 2"),
    (7, b"\x02", "flags"),
    (56, b"\x00", "n_inputs 0"),
    (DOM, struct.pack("<d", float("nan")), "non-finite"),
    (DOM + 16, struct.pack("<d", 0.1), "input_min > input_max"),
    (OUT0, b"\x07", "unknown pose code 7"),
    (OUT1, b"\x00", "strictly increasing"),
    (OUT0 + 1, b"\x02", "d_slot 2, expected 0 or 1"),
    (OUT1 + 1, b"\x01", "d_slot 1, expected 0"),
    (OUT0 + 1, b"\x00", "dx is not an output before thx that feeds"),
    (TERMS0, b"\x05", "element 5"),
    (TERMS0 + 1, b"\x0b", "unknown exponent code 11"),
    (TERMS0 + 2, b"\x04", "unknown multiplier code 4"),
    (TERMS0 + 3, b"\x01", "reserved"),
    (TERMS1 + 2, b"\x02", "dy is not an output before thx"),
    (TERMS0 + 4, b"\x00\x04", "lists a term twice"),  # v2^2 -> v1^-1
    (TERMS0 + 4, b"\x01\x04", "needs input_min of v2 > 0"),  # v2^2 -> v2^-1
    (TERMS0, b"\xff", "bare displacement"),
    (40, b"\x01", "sensor id"),
])
def test_bad_fields_are_named(offset, value, words):
    blob = bytearray(to_blob(small_model(), "double"))
    blob[offset:offset + len(value)] = value
    with pytest.raises(InputError, match=words):
        from_blob(reseal(blob))


def test_bad_counts_are_refused():
    blob = bytearray(to_blob(small_model(), "double"))
    blob[58:60] = struct.pack("<H", 5)
    with pytest.raises(InputError, match="sum to 4, the header says 5"):
        from_blob(reseal(blob))
    blob = bytearray(to_blob(small_model(), "double"))
    blob[OUT0 + 2:OUT0 + 4] = struct.pack("<H", 3)
    with pytest.raises(InputError):
        from_blob(reseal(blob))
    blob = bytearray(to_blob(small_model(), "double"))
    blob[-1] ^= 1
    with pytest.raises(InputError, match="CRC mismatch"):
        from_blob(bytes(blob))


def test_to_blob_refuses_what_cannot_be_stored():
    m = small_model()
    with pytest.raises(InputError, match="longer than 16"):
        to_blob(m, sensor_id="x" * 17)
    with pytest.raises(InputError, match="ASCII"):
        to_blob(m, sensor_id="capteur-é")
    with pytest.raises(InputError, match="precision"):
        to_blob(m, "fixed")
    wide = Model(np.ones(31), np.full(31, 2.0), (Equation("dx", 0.0, (parse_term("v31^1"),), (1.0,)),))
    with pytest.raises(InputError, match="31 inputs"):
        to_blob(wide)
    big = Model(np.array([0.5, -1.0]), np.array([2.0, 1.0]),
                (Equation("dx", 0.0, (parse_term("v2^1"),), (1e39,)),))
    for precision in ("float", "double"):  # as fitgen codegen refuses it
        with pytest.raises(InputError, match="over the"):
            to_blob(big, precision)
    assert from_blob(to_blob(m, sensor_id="")).sensor_id == ""
