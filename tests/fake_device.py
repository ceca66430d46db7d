"""A small in-process device: the protocol side of the firmware (docs/protocol.md) in Python.

It serves one host on a pty (the host opens ``/dev/pts/N``) or a TCP socket
(``socket://127.0.0.1:PORT``), evaluates with ``Model.predict`` (so a float build
is not bit-exact with float C) and loads calibration blobs through
``fitgen.c.calblob.from_blob``. A reference for the real firmware's replies, not a
model of its timing.
"""

from __future__ import annotations

import os
import select
import socket
import struct
import threading
import time
import tty

import numpy as np

from fitgen.c.calblob import from_blob, rounded_model
from fitgen.base.errors import InputError
from host import protocol as p
from host.protocol import ErrorCode as E
from host.protocol import MsgType as T


class Reject(Exception):
    def __init__(self, code: E):
        self.code = code


class FakeDevice:
    def __init__(self, model, precision: str = "double", *, transport: str = "pty", sensor_id: str = "paper",
                 capacity: int = 16384, mute: bool = False, stale: bool = False, corrupt_read: bool = False,
                 boot: float = 0.0, adc_chips: tuple = ()):
        self.precision = precision
        self.dtype = p.real_dtype(precision)
        self.compiled = model if precision != "float" else rounded_model(model, "float")
        self.compiled_hash = model.sha256
        self.sensor_id = sensor_id
        self.capacity = capacity
        self.adc_chips = adc_chips  # INFO's ADC block: a firmware that reads its inputs from these chips
        self.mute = mute  # never answer
        # what comes within boot s of the host's connecting (a socket) or of the start (a pty) is lost, as on an
        # Uno, whose port's opening resets it into its bootloader
        self.boot = boot
        self.stale = stale  # send a stale reply (another seq) and garbage before every reply
        self.corrupt_read = corrupt_read  # flip a bit of CAL_READ replies
        self.n_inputs, self.n_outputs = model.n_inputs, len(model.equations)
        self.active = None  # (blob, BlobInfo) of a loaded calibration
        self.staging = None  # [size, crc, bytearray]
        self.stream_state = None  # [seq, period_s, remaining, next_time, index]
        self.reader = p.FrameReader()
        self.requests: list[p.Frame] = []
        self._stop = threading.Event()
        self._t0 = time.monotonic()
        if transport == "pty":
            self._master, self._slave = os.openpty()
            tty.setraw(self._slave)
            self.url = os.ttyname(self._slave)
            self._listener = None
            self._fd = self._master
        else:
            self._listener = socket.create_server(("127.0.0.1", 0))
            self.url = f"socket://127.0.0.1:{self._listener.getsockname()[1]}"
            self._fd = None
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    # --- life ---------------------------------------------------------------------

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
        for fd in (getattr(self, "_master", None), getattr(self, "_slave", None)):
            if fd is not None:
                os.close(fd)
        if self._listener is not None:
            self._listener.close()
            if self._conn is not None:
                self._conn.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    _conn = None

    def _run(self) -> None:
        if self._listener is not None:
            self._listener.settimeout(0.05)
            while not self._stop.is_set() and self._conn is None:
                try:
                    self._conn, _ = self._listener.accept()
                except socket.timeout:
                    continue
            if self._conn is None:
                return
            self._fd = self._conn.fileno()
        booted = time.monotonic() + self.boot
        while not self._stop.is_set():
            ready, _, _ = select.select([self._fd], [], [], 0.005)
            if ready:
                try:
                    data = os.read(self._fd, 4096)
                except OSError:
                    data = b""
                if not data and self._listener is not None:
                    return  # the host closed the socket
                if time.monotonic() < booted:
                    continue
                for ev in self.reader.events(data):
                    if self.mute:
                        continue
                    if isinstance(ev, p.ProtocolError):
                        self._send(T.ERROR, 0, p.pack_error(ev.kind, 0))
                    else:
                        self._handle(ev)
            self._tick_stream()

    def _send(self, type: int, seq: int, payload: bytes = b"") -> None:
        data = p.encode_frame(type, seq, payload)
        while data:
            n = os.write(self._fd, data)
            data = data[n:]

    # --- requests -----------------------------------------------------------------

    @property
    def model(self):
        return self.active[1].model if self.active else self.compiled

    @property
    def fma(self) -> bool:
        return self.active[1].fma if self.active else False

    def _handle(self, f: p.Frame) -> None:
        self.requests.append(f)
        self.stream_state = None  # any request stops a running stream
        try:
            handler = getattr(self, f"_on_{T(f.type).name.lower()}", None) if f.type in T._value2member_map_ else None
            if handler is None or f.type & p.REPLY:
                raise Reject(E.UNKNOWN_TYPE)
            reply = handler(f.payload, f.seq)
        except Reject as r:
            self._send(T.ERROR, f.seq, p.pack_error(r.code, f.type))
            return
        if self.stale:
            self._send(f.type | p.REPLY, (f.seq - 2) % 255 + 1, b"stale")
            os.write(self._fd, b"\x03\x01\x00")  # garbage: a frame that decodes short
        self._send(f.type | p.REPLY, f.seq, reply)

    @staticmethod
    def _length(payload: bytes, n: int) -> None:
        if len(payload) != n:
            raise Reject(E.BAD_LENGTH)

    def _on_ping(self, payload, seq):
        return payload

    def _on_info(self, payload, seq):
        self._length(payload, 0)
        info = p.DeviceInfo(p.PROTOCOL_VERSION, self.precision, self.n_inputs, self.n_outputs,
                            1 if self.active else 0, 0, p.MAX_PAYLOAD,
                            self.active[1].model_hash if self.active else self.compiled_hash,
                            self.active[1].sensor_id if self.active else self.sensor_id, "fake-0.1",
                            self.adc_chips, dict.fromkeys(p.ADC_COUNTS, 0)
                            if self.adc_chips else None)
        return p.pack_info(info)

    def _estimate(self, x: np.ndarray):
        out, status = self.model.predict(x, with_status=True, fma=self.fma)
        return status, out

    def _on_eval(self, payload, seq):
        row = self.n_inputs * self.dtype.itemsize
        k = len(payload) // row
        if not payload or len(payload) % row or k > p.max_eval_batch(self.n_inputs, self.n_outputs,
                                                                      self.dtype.itemsize):
            raise Reject(E.BAD_LENGTH)
        x = np.frombuffer(payload, dtype=self.dtype).astype(float).reshape(k, self.n_inputs)
        status, out = self._estimate(x)
        return p.pack_eval_reply(status, out, self.dtype)

    def _on_stream(self, payload, seq):
        self._length(payload, p.STREAM.size)
        period, count = p.STREAM.unpack(payload)
        if count and not period:
            raise Reject(E.BAD_ARG)
        if count:
            self.stream_state = [seq, period / 1000, count, time.monotonic() + period / 1000, 0]
        return b""

    def _tick_stream(self) -> None:
        s = self.stream_state
        if s is None or time.monotonic() < s[3]:
            return
        seq, period, remaining, _, index = s
        m = self.model
        x = (m.input_min + (m.input_max - m.input_min) * (0.5 + 0.1 * np.sin(index + np.arange(m.n_inputs))))
        status, out = self._estimate(x[None, :])
        ms = int((time.monotonic() - self._t0) * 1000)
        self._send(T.STREAM_SAMPLE, seq, p.pack_stream_sample(index, ms, int(status[0]), x, out[0], self.dtype))
        s[2:] = [remaining - 1, s[3] + period, index + 1]
        if s[2] == 0:
            self.stream_state = None

    def _on_cal_begin(self, payload, seq):
        self._length(payload, p.CAL_BEGIN.size)
        size, crc = p.CAL_BEGIN.unpack(payload)
        self.staging = None
        if not 0 < size <= self.capacity:
            raise Reject(E.BAD_ARG)
        self.staging = [size, crc, bytearray()]
        return b""

    def _on_cal_data(self, payload, seq):
        head = p.CAL_DATA.size
        if not head + 1 <= len(payload) <= head + p.CAL_DATA_MAX:
            raise Reject(E.BAD_LENGTH)
        (offset,) = p.CAL_DATA.unpack_from(payload)
        st = self.staging
        if st is None or offset != len(st[2]) or offset + len(payload) - head > st[0]:
            raise Reject(E.CAL_SEQUENCE)
        st[2] += payload[head:]
        return p.CAL_DATA_REPLY.pack(len(st[2]))

    def _on_cal_commit(self, payload, seq):
        self._length(payload, 0)
        st, self.staging = self.staging, None
        if st is None or len(st[2]) != st[0]:
            raise Reject(E.CAL_SEQUENCE)
        blob = bytes(st[2])
        if p.crc32(blob) != st[1] or p.crc32(blob[:-4]) != struct.unpack("<I", blob[-4:])[0]:
            raise Reject(E.CAL_CRC)
        try:
            info = from_blob(blob)
        except InputError:
            raise Reject(E.CAL_INVALID) from None
        if (info.precision, info.model.n_inputs, len(info.model.equations)) != \
                (self.precision, self.n_inputs, self.n_outputs):
            raise Reject(E.CAL_INVALID)
        self.active = (blob, info)
        return bytes.fromhex(info.model_hash)

    def _on_cal_read(self, payload, seq):
        self._length(payload, p.CAL_READ.size)
        offset, length = p.CAL_READ.unpack(payload)
        if self.active is None:
            raise Reject(E.NO_CAL)
        if not 1 <= length <= p.CAL_READ_MAX:
            raise Reject(E.BAD_ARG)
        out = bytearray(self.active[0][offset:offset + length])
        if self.corrupt_read and out:
            out[-1] ^= 0x10
        return bytes(out)

    def _on_cal_reset(self, payload, seq):
        self._length(payload, 0)
        self.active = None
        return b""

    def _on_bench(self, payload, seq):
        self._length(payload, p.BENCH.size)
        (n,) = p.BENCH.unpack(payload)
        if not 1 <= n <= p.BENCH_MAX:
            raise Reject(E.BAD_ARG)
        m = self.model
        x = m.input_min + (m.input_max - m.input_min) * np.linspace(0.05, 0.95, 16)[:, None]
        rounds = min(max(1, n // 16), 20)  # timed on a few rounds, scaled to n
        t = time.perf_counter_ns()
        for _ in range(rounds):
            self._estimate(x)
        return p.pack_bench(int((time.perf_counter_ns() - t) * n / (16 * rounds)), 1_000_000_000, n)
