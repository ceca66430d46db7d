"""The serial protocol of docs/protocol.md as pure functions: COBS, CRC-32, frames, payloads. No I/O.

    wire frame = COBS(body) 0x00
    body       = type:u8 seq:u8 len:u16 payload[len] crc:u32   (little-endian, crc = zlib.crc32)

Its numbers and fixed records (:data:`LAYOUTS`) are the one description of the protocol: the firmware
builds with them, rendered into C by :mod:`host.protocol_c`.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from enum import IntEnum
from typing import Iterator, NamedTuple

import numpy as np

from fitgen.base.layout import Layout

PROTOCOL_VERSION = 1
MAX_PAYLOAD = 256
HEADER = Layout(("type", "B"), ("seq", "B"), ("len", "H"), then="payload[len], crc:u32")
HEADER_SIZE = HEADER.size  # 4
CRC = Layout(("crc", "I"))
CRC_SIZE = CRC.size  # 4
MIN_BODY = HEADER_SIZE + CRC_SIZE  # 8
MAX_BODY = MIN_BODY + MAX_PAYLOAD  # 264
MAX_ENCODED = 267  # the largest encoded frame the device accepts before the delimiter
CAL_DATA_MAX = 248  # blob bytes per CAL_DATA (plus the 4-byte offset)
CAL_READ_MAX = 256
CAL_MAX_BLOB = 4096  # the largest blob the format lets a device hold (firmware cal.h CAL_CAPACITY)
BENCH_MAX = 1_000_000  # estimates per BENCH
HASH_SIZE = 32
SENSOR_ID_SIZE = 16
FW_VERSION_SIZE = 12
REPLY = 0x80  # reply type = request type | REPLY
ADC_COUNTS = ("nack", "timeout", "stuck", "other", "retries", "resets")
ADC_KINDS = ("ads1115", "ads7828")

# the fixed records of the payloads
INFO = Layout(("version", "B"), ("precision", "B"), ("n_inputs", "B"), ("n_outputs", "B"), ("cal_source", "B"),
              ("style", "B"), ("max_payload", "H"), ("hash", f"{HASH_SIZE}s"), ("sensor_id", f"{SENSOR_ID_SIZE}s"),
              ("fw_version", f"{FW_VERSION_SIZE}s"), then="the ADC block")
INFO_SIZE = INFO.size  # 68
ADC_BLOCK = Layout(("chips", "B"), then="chips x ADC_CHIP, then I2C_COUNTS")
ADC_CHIP = Layout(("kind", "B"), ("address", "B"), ("inputs", "B"), ("pga", "B"), ("rate", "B"), ("mode", "B"))
I2C_COUNTS = Layout(*((name, "I") for name in ADC_COUNTS))
EVAL_RESULT = Layout(("status", "i"), then="n_outputs reals")
STREAM = Layout(("period_ms", "H"), ("count", "H"))
SAMPLE = Layout(("index", "H"), ("time_ms", "I"), ("status", "i"), then="n_inputs reals, n_outputs reals")
CAL_BEGIN = Layout(("total", "I"), ("crc", "I"))
CAL_DATA = Layout(("offset", "I"), then="1..CAL_DATA_MAX blob bytes")
CAL_DATA_REPLY = Layout(("received", "I"))
CAL_READ = Layout(("offset", "I"), ("length", "H"))
BENCH = Layout(("n", "I"))
BENCH_REPLY = Layout(("ticks", "Q"), ("tick_hz", "I"), ("n", "I"))
ERROR = Layout(("code", "B"), ("request_type", "B"))
LAYOUTS = {"HEADER": HEADER, "INFO": INFO, "ADC_BLOCK": ADC_BLOCK, "ADC_CHIP": ADC_CHIP, "I2C_COUNTS": I2C_COUNTS,
           "EVAL_RESULT": EVAL_RESULT, "STREAM": STREAM, "SAMPLE": SAMPLE, "CAL_BEGIN": CAL_BEGIN,
           "CAL_DATA": CAL_DATA, "CAL_DATA_REPLY": CAL_DATA_REPLY, "CAL_READ": CAL_READ, "BENCH": BENCH,
           "BENCH_REPLY": BENCH_REPLY, "ERROR": ERROR}


class MsgType(IntEnum):
    PING = 0x01
    INFO = 0x02
    EVAL = 0x03
    STREAM = 0x04
    CAL_BEGIN = 0x05
    CAL_DATA = 0x06
    CAL_COMMIT = 0x07
    CAL_READ = 0x08
    CAL_RESET = 0x09
    BENCH = 0x0A
    STREAM_SAMPLE = 0x85
    ERROR = 0xFF


class ErrorCode(IntEnum):
    BAD_CRC = 1
    BAD_FRAME = 2
    OVERSIZE = 3
    UNKNOWN_TYPE = 4
    BAD_LENGTH = 5
    CAL_SEQUENCE = 6
    CAL_CRC = 7
    CAL_INVALID = 8
    NO_CAL = 9
    BAD_ARG = 10


PRECISIONS = ("double", "float", "fixed")  # INFO's precision code is the index
REAL_DTYPES = {"double": "<f8", "float": "<f4", "fixed": "<i4"}


class ProtocolError(ValueError):
    """Bytes that break the protocol; ``kind`` is the ErrorCode the device would answer with."""

    def __init__(self, kind: ErrorCode, message: str = ""):
        self.kind = ErrorCode(kind)
        super().__init__(message or self.kind.name)


def type_name(t: int) -> str:
    try:
        return MsgType(t).name
    except ValueError:
        return f"0x{t:02x}"


def error_name(code: int) -> str:
    try:
        return ErrorCode(code).name
    except ValueError:
        return f"error {code}"


# --- COBS and CRC ---------------------------------------------------------------


def cobs_encode(data: bytes) -> bytes:
    """COBS (Cheshire and Baker) of ``data``: no 0x00 in the result; the delimiter is not added.

    Canonical form: a full 254-byte block at the very end gets no empty block after it.
    """
    out = bytearray()
    block = bytearray()
    full = False  # the last block written was a full (0xFF) one with no zero after it
    for b in data:
        if b == 0:
            out.append(len(block) + 1)
            out += block
            block.clear()
            full = False
        else:
            block.append(b)
            if len(block) == 254:
                out.append(0xFF)
                out += block
                block.clear()
                full = True
    if block or not full:
        out.append(len(block) + 1)
        out += block
    return bytes(out)


def cobs_decode(data: bytes) -> bytes:
    """The bytes ``data`` (without its delimiter) encodes; ProtocolError(BAD_FRAME) if it is not COBS."""
    data = bytes(data)
    if not data:
        raise ProtocolError(ErrorCode.BAD_FRAME, "COBS: empty input")
    out = bytearray()
    i, n = 0, len(data)
    while i < n:
        code = data[i]
        if code == 0:
            raise ProtocolError(ErrorCode.BAD_FRAME, f"COBS: a zero byte at {i}")
        end = i + code
        if end > n:
            raise ProtocolError(ErrorCode.BAD_FRAME, f"COBS: the block at {i} runs {end - n} bytes past the end")
        block = data[i + 1:end]
        if 0 in block:
            raise ProtocolError(ErrorCode.BAD_FRAME, f"COBS: a zero byte at {i + 1 + block.index(0)}")
        out += block
        i = end
        if code != 0xFF and i < n:
            out.append(0)
    return bytes(out)


def crc32(data: bytes, value: int = 0) -> int:
    """CRC-32 (IEEE 802.3, zlib.crc32), as an unsigned 32-bit number."""
    return zlib.crc32(data, value) & 0xFFFFFFFF


# --- frames ---------------------------------------------------------------------


@dataclass(frozen=True)
class Frame:
    type: int
    seq: int
    payload: bytes = b""

    @property
    def is_error(self) -> bool:
        return self.type == MsgType.ERROR


def frame_body(type: int, seq: int, payload: bytes = b"", crc: int | None = None) -> bytes:
    """The unencoded body; no MAX_PAYLOAD check (fuzzers build bad frames with it); ``crc`` overrides."""
    payload = bytes(payload)
    head = HEADER.pack(type, seq, len(payload)) + payload
    return head + CRC.pack(crc32(head) if crc is None else crc)


def encode_frame(type: int, seq: int, payload: bytes = b"") -> bytes:
    """COBS(body) + 0x00, ready for the wire."""
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"payload of {len(payload)} bytes is over MAX_PAYLOAD ({MAX_PAYLOAD})")
    return cobs_encode(frame_body(type, seq, payload)) + b"\x00"


def decode_frame(encoded: bytes) -> Frame:
    """The Frame of one encoded body (delimiter removed); ProtocolError(BAD_FRAME or BAD_CRC) otherwise."""
    body = cobs_decode(encoded)
    if len(body) < MIN_BODY:
        raise ProtocolError(ErrorCode.BAD_FRAME, f"frame body of {len(body)} bytes is shorter than {MIN_BODY}")
    if len(body) > MAX_BODY:
        raise ProtocolError(ErrorCode.BAD_FRAME, f"frame body of {len(body)} bytes is longer than {MAX_BODY}")
    type_, seq, length = HEADER.unpack_from(body)
    if length != len(body) - MIN_BODY:
        raise ProtocolError(ErrorCode.BAD_FRAME, f"len {length} disagrees with a body of {len(body)} bytes")
    (crc,) = CRC.unpack_from(body, len(body) - CRC_SIZE)
    if crc != crc32(body[:-CRC_SIZE]):
        raise ProtocolError(ErrorCode.BAD_CRC, f"CRC mismatch: frame says {crc:08x}, "
                                               f"body gives {crc32(body[:-CRC_SIZE]):08x}")
    return Frame(type_, seq, body[HEADER_SIZE:-CRC_SIZE])


class FrameReader:
    """Fed bytes in any pieces, gives back complete frames, as the device receives them.

    An empty frame (two delimiters) is ignored. More than MAX_ENCODED bytes before a
    delimiter: everything up to the next 0x00 is dropped, reported once as OVERSIZE.
    ``events`` yields Frames and ProtocolErrors in order; ``feed`` keeps the frames
    and counts the errors in ``errors``.
    """

    def __init__(self, max_encoded: int = MAX_ENCODED):
        self.max_encoded = max_encoded
        self._buf = bytearray()
        self._dropping = False
        self.errors: list[ProtocolError] = []

    def events(self, data: bytes) -> Iterator[Frame | ProtocolError]:
        start = 0
        data = bytes(data)
        while start <= len(data):
            end = data.find(b"\x00", start)
            piece = data[start:] if end < 0 else data[start:end]
            if not self._dropping:
                self._buf += piece
                if len(self._buf) > self.max_encoded:
                    self._buf.clear()
                    self._dropping = True
                    yield ProtocolError(ErrorCode.OVERSIZE, f"no delimiter within {self.max_encoded} bytes")
            if end < 0:
                return
            if not self._dropping and self._buf:
                try:
                    yield decode_frame(bytes(self._buf))
                except ProtocolError as exc:
                    yield exc
            self._buf.clear()
            self._dropping = False
            start = end + 1

    def feed(self, data: bytes) -> list[Frame]:
        frames = []
        for ev in self.events(data):
            if isinstance(ev, Frame):
                frames.append(ev)
            else:
                self.errors.append(ev)
        return frames

    @property
    def pending(self) -> int:
        """Bytes held of a frame not yet delimited."""
        return len(self._buf)


# --- payloads -------------------------------------------------------------------


def real_dtype(precision: str) -> np.dtype:
    try:
        return np.dtype(REAL_DTYPES[precision])
    except KeyError:
        raise ValueError(f"unknown precision {precision!r} (one of {', '.join(REAL_DTYPES)})") from None


def max_eval_batch(n_inputs: int, n_outputs: int, real_size: int) -> int:
    """Largest k of one EVAL: k input vectors and k results (status + outputs) each fit MAX_PAYLOAD."""
    return min(MAX_PAYLOAD // (n_inputs * real_size), MAX_PAYLOAD // (4 + n_outputs * real_size))


def pack_eval(inputs: np.ndarray, real_dtype) -> bytes:
    """EVAL request payload: rows of inputs as little-endian reals (fixed: int32 as given)."""
    arr = np.atleast_2d(np.asarray(inputs))
    dt = np.dtype(real_dtype)
    if dt.kind == "f":
        with np.errstate(over="ignore"):
            return arr.astype(float).astype(dt).tobytes()
    return arr.astype(dt).tobytes()


def _eval_dtype(n_outputs: int, real_dtype) -> np.dtype:
    head = [(name, "<" + code) for name, code in EVAL_RESULT.fields]
    return np.dtype(head + [("out", np.dtype(real_dtype), (n_outputs,))])


def unpack_eval_reply(payload: bytes, n_outputs: int, real_dtype) -> tuple[np.ndarray, np.ndarray]:
    """Status (k,) int and outputs (k, n_outputs) float of an EVAL reply."""
    dt = _eval_dtype(n_outputs, real_dtype)
    if len(payload) % dt.itemsize:
        raise ProtocolError(ErrorCode.BAD_LENGTH, f"EVAL reply of {len(payload)} bytes is not a multiple of "
                                                  f"{dt.itemsize} (status + {n_outputs} outputs)")
    rec = np.frombuffer(bytes(payload), dtype=dt)
    return rec["status"].astype(np.int64), rec["out"].astype(float).reshape(len(rec), n_outputs)


def pack_eval_reply(status, outputs, real_dtype) -> bytes:
    """The device side of EVAL (fake devices and tests)."""
    outputs = np.atleast_2d(np.asarray(outputs, dtype=float))
    rec = np.zeros(len(outputs), dtype=_eval_dtype(outputs.shape[1], real_dtype))
    rec["status"] = np.asarray(status)
    rec["out"] = outputs
    return rec.tobytes()


def _text(raw: bytes) -> str:
    return raw.split(b"\0", 1)[0].decode("ascii", errors="replace")


@dataclass(frozen=True)
class DeviceInfo:
    protocol_version: int
    precision: str  # double, float, fixed
    n_inputs: int
    n_outputs: int
    cal_source: int  # 0 compiled in, 1 loaded blob
    style: int  # of the compiled-in model: 0 table, 1 unrolled
    max_payload: int
    model_hash: str  # hex
    sensor_id: str
    firmware_version: str
    # the ADC block after the 68 bytes (firmware that reads ADCs): chips and I2C counts; None before it
    adc_chips: tuple = ()  # per chip: (kind "ads1115" | "ads7828", address, inputs, PGA code, rate code, mode)
    adc_counts: dict | None = None  # nack, timeout, stuck, other, retries, resets

    @property
    def real_dtype(self) -> np.dtype:
        return real_dtype(self.precision)

    @property
    def real_size(self) -> int:
        return self.real_dtype.itemsize

    @property
    def calibration(self) -> str:
        return {0: "compiled-in", 1: "loaded"}.get(self.cal_source, f"source {self.cal_source}")

    @property
    def style_name(self) -> str:
        return {0: "table", 1: "unrolled"}.get(self.style, f"style {self.style}")


def unpack_info(payload: bytes) -> DeviceInfo:
    """INFO's 68 bytes, and the ADC block a firmware that reads ADCs appends (docs/protocol.md)."""
    payload = bytes(payload)
    if len(payload) < INFO_SIZE:
        raise ProtocolError(ErrorCode.BAD_LENGTH, f"INFO reply of {len(payload)} bytes (expected {INFO_SIZE} or more)")
    ver, prec, n_in, n_out, src, style, maxp, h, sid, fw = INFO.unpack(payload[:INFO_SIZE])
    if prec >= len(PRECISIONS):
        raise ProtocolError(ErrorCode.BAD_ARG, f"INFO: unknown precision code {prec}")
    chips, counts = (), None
    if len(payload) > INFO_SIZE:
        (n,) = ADC_BLOCK.unpack_from(payload, INFO_SIZE)
        start = INFO_SIZE + ADC_BLOCK.size
        end = start + ADC_CHIP.size * n
        if len(payload) != end + I2C_COUNTS.size:
            raise ProtocolError(ErrorCode.BAD_LENGTH, f"INFO reply of {len(payload)} bytes: its ADC block for {n} "
                                                      f"chips needs {end + I2C_COUNTS.size}")
        chips = tuple((ADC_KINDS[r[0]] if r[0] < len(ADC_KINDS) else f"kind {r[0]}",) + tuple(r[1:])
                      for r in (ADC_CHIP.unpack_from(payload, i) for i in range(start, end, ADC_CHIP.size)))
        counts = dict(zip(ADC_COUNTS, I2C_COUNTS.unpack(payload[end:])))
    return DeviceInfo(ver, PRECISIONS[prec], n_in, n_out, src, style, maxp, h.hex(), _text(sid), _text(fw),
                      chips, counts)


def pack_info(info: DeviceInfo) -> bytes:
    """The device side of INFO (fake devices and tests); the ADC block when ``adc_counts`` is set."""
    head = INFO.pack(info.protocol_version, PRECISIONS.index(info.precision), info.n_inputs, info.n_outputs,
                      info.cal_source, info.style, info.max_payload, bytes.fromhex(info.model_hash),
                      info.sensor_id.encode("ascii"), info.firmware_version.encode("ascii"))
    if info.adc_counts is None:
        return head
    chips = b"".join(ADC_CHIP.pack(ADC_KINDS.index(c[0]), *c[1:]) for c in info.adc_chips)
    counts = I2C_COUNTS.pack(*(info.adc_counts[k] for k in ADC_COUNTS))
    return head + ADC_BLOCK.pack(len(info.adc_chips)) + chips + counts


class StreamSample(NamedTuple):
    index: int
    time_ms: int
    status: int
    inputs: np.ndarray
    outputs: np.ndarray


def stream_sample_size(n_inputs: int, n_outputs: int, real_size: int) -> int:
    return SAMPLE.size + (n_inputs + n_outputs) * real_size


def unpack_stream_sample(payload: bytes, n_inputs: int, n_outputs: int, real_dtype) -> StreamSample:
    dt = np.dtype(real_dtype)
    want = stream_sample_size(n_inputs, n_outputs, dt.itemsize)
    if len(payload) != want:
        raise ProtocolError(ErrorCode.BAD_LENGTH, f"STREAM sample of {len(payload)} bytes (expected {want})")
    index, time_ms, status = SAMPLE.unpack_from(payload)
    vals = np.frombuffer(bytes(payload), dtype=dt, offset=SAMPLE.size).astype(float)
    return StreamSample(index, time_ms, status, vals[:n_inputs], vals[n_inputs:])


def pack_stream_sample(index: int, time_ms: int, status: int, inputs, outputs, real_dtype) -> bytes:
    vals = np.concatenate([np.ravel(inputs), np.ravel(outputs)]).astype(float).astype(np.dtype(real_dtype))
    return SAMPLE.pack(index & 0xFFFF, time_ms & 0xFFFFFFFF, status) + vals.tobytes()


class BenchResult(NamedTuple):
    ticks: int
    tick_hz: int
    n: int

    @property
    def seconds(self) -> float:
        return self.ticks / self.tick_hz if self.tick_hz else float("nan")

    @property
    def per_estimate_us(self) -> float:
        return 1e6 * self.seconds / self.n if self.n else float("nan")


def unpack_bench(payload: bytes) -> BenchResult:
    if len(payload) != BENCH_REPLY.size:
        raise ProtocolError(ErrorCode.BAD_LENGTH, f"BENCH reply of {len(payload)} bytes (expected {BENCH_REPLY.size})")
    return BenchResult(*BENCH_REPLY.unpack(bytes(payload)))


def pack_bench(ticks: int, tick_hz: int, n: int) -> bytes:
    return BENCH_REPLY.pack(ticks, tick_hz, n)


# request payloads
def pack_stream(period_ms: int, count: int) -> bytes:
    return STREAM.pack(period_ms, count)


def pack_cal_begin(size: int, crc: int) -> bytes:
    return CAL_BEGIN.pack(size, crc)


def pack_cal_data(offset: int, chunk: bytes) -> bytes:
    return CAL_DATA.pack(offset) + bytes(chunk)


def pack_cal_read(offset: int, length: int) -> bytes:
    return CAL_READ.pack(offset, length)


def pack_bench_request(n: int) -> bytes:
    return BENCH.pack(n)


def pack_error(code: int, request_type: int) -> bytes:
    return ERROR.pack(code, request_type)


def unpack_error(payload: bytes) -> tuple[int, int]:
    if len(payload) != ERROR.size:
        raise ProtocolError(ErrorCode.BAD_LENGTH, f"ERROR reply of {len(payload)} bytes (expected {ERROR.size})")
    return ERROR.unpack(bytes(payload))
