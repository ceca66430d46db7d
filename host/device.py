"""A client of the device protocol (docs/protocol.md) over a serial port, a pty or a TCP socket (pyserial)."""

from __future__ import annotations

import select
import time

import numpy as np

from fitgen.base.errors import InputError

from host import protocol as p
from host.channelmap import check_reported_full_scale
from host.protocol import DeviceInfo, ErrorCode, Frame, MsgType

POLL = 0.02  # seconds one read of the port blocks at most
READ_CHUNK = 4096  # bytes taken from a socket at once
# a board that restarts when its port opens (an Uno: DTR resets it) runs its bootloader first (optiboot
# waits 1 s for an upload): the CLIs give a board this long to answer its first PING
BOOT_WAIT = 3.0
PING_EVERY = 0.25  # seconds between two PINGs while a board starts


class NoAnswer(InputError):
    """The device did not answer in time (a port with nothing behind it, or a hung device)."""


class DeviceError(Exception):
    """The device answered a request with ERROR."""

    def __init__(self, code: int, request_type: int):
        self.code = code
        self.request_type = request_type
        super().__init__(f"the device answered {p.type_name(request_type)} with ERROR {p.error_name(code)}")


def port_error(exc: BaseException) -> str:
    """The OS's words for why a port failed ("connection refused"), else pyserial's first line."""
    for e in (exc.__cause__, exc.__context__, exc):
        if isinstance(e, OSError) and e.strerror:
            return e.strerror[:1].lower() + e.strerror[1:]
        if isinstance(e, (TypeError, KeyError)):
            # pyserial's URL handlers fail so on a missing or out-of-range port ('<=' not supported ...)
            return "expected HOST:PORT after the scheme, a port from 1 to 65535 (e.g. socket://127.0.0.1:5000)"
    text = str(exc).strip() or type(exc).__name__
    return text.splitlines()[0]


def url_hint(url: str) -> str:
    """What a port URL that failed to open probably meant: '' or '; ...' (a TCP port without its scheme, a file)."""
    import os
    import re

    if re.fullmatch(r"[\w.-]+:\d{1,5}", url) and not os.path.exists(url):
        return f"; a TCP port is given as socket://{url}"
    if os.path.isfile(url):
        return "; it is a regular file, not a serial device (/dev/tty...) or a URL such as socket://HOST:PORT"
    if _no_terminal(url):  # pyserial says 'Inappropriate ioctl for device' in its own words
        return "; it is a device but no serial port (a controller's is /dev/ttyUSB* or /dev/ttyACM*: ls /dev/serial/by-id)"
    return ""


def _no_terminal(path: str) -> bool:
    """Whether ``path`` is a character device that is not a terminal (/dev/null, /dev/zero)."""
    import os
    import stat

    try:
        if not stat.S_ISCHR(os.stat(path).st_mode):
            return False
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY)
    except OSError:
        return False
    try:
        return not os.isatty(fd)
    finally:
        os.close(fd)


def no_nagle(port) -> None:
    """On a pyserial socket:// port, send small frames at once: no Nagle wait (40 ms with delayed ACKs)."""
    sock = getattr(port, "_socket", None)
    if sock is not None:
        import socket

        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)


class PortOwner:
    """Something that holds an open pyserial port as ``port`` until ``close``."""

    def close(self) -> None:
        if self.port is not None:
            try:
                self.port.close()
            finally:
                self.port = None


class Device(PortOwner):
    """Requests and replies over one open port. Use ``Device.open(url)`` as a context manager."""

    def __init__(self, port, timeout: float = 1.0, name: str = ""):
        self.port = port
        self.timeout = float(timeout)
        self.name = name or getattr(port, "name", "") or "device"
        self.reader = p.FrameReader()
        self._seq = 0
        self._info: DeviceInfo | None = None
        self._backlog: list[Frame] = []
        # pyserial's socket:// reports at most 1 byte waiting, so reading what in_waiting says takes a
        # frame 2 bytes a turn: a socket is read directly, everything it holds at once
        self._sock = getattr(port, "_socket", None)

    @classmethod
    def open(cls, url: str, timeout: float = 1.0, ready: float = 0.0) -> "Device":
        """The device at ``url``; with ``ready`` > 0, once it has answered a PING (:meth:`wait_ready`)."""
        import serial

        try:
            port = serial.serial_for_url(url, baudrate=115200, timeout=POLL, write_timeout=max(timeout, POLL))
        except (serial.SerialException, ValueError, OSError) as exc:
            raise InputError(f"cannot open port {url}: {port_error(exc)}{url_hint(url)}") from None
        no_nagle(port)
        dev = cls(port, timeout, url)
        if ready > 0:
            try:
                dev.wait_ready(ready)
            except BaseException:
                dev.close()
                raise
        return dev

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # --- frames -----------------------------------------------------------------

    def next_seq(self) -> int:
        self._seq = self._seq % 255 + 1
        return self._seq

    def send_raw(self, data: bytes) -> None:
        """Write bytes as they are (fuzzing, or a frame built by hand)."""
        import serial

        try:
            self.port.write(bytes(data))
            self.port.flush()
        except serial.SerialTimeoutException:
            raise NoAnswer(f"{self.name}: the device does not take the bytes written to it") from None
        except (serial.SerialException, OSError) as exc:
            raise InputError(f"{self.name}: {port_error(exc)}") from None

    def send(self, type: int, seq: int, payload: bytes = b"") -> None:
        self.send_raw(p.encode_frame(type, seq, payload))

    def receive(self, timeout: float | None = None) -> Frame | None:
        """The next frame from the device, or None after ``timeout`` s. Undecodable bytes count in reader.errors."""
        import serial

        if self._backlog:
            return self._backlog.pop(0)
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        while True:
            try:
                data = self._read_some()
            except (serial.SerialException, OSError) as exc:
                raise InputError(f"{self.name}: {port_error(exc)}") from None
            if data:
                self._backlog += self.reader.feed(data)
                if self._backlog:
                    return self._backlog.pop(0)
            if time.monotonic() >= deadline:
                return None

    def _read_some(self) -> bytes:
        """The bytes the port holds, after waiting up to POLL s for the first one (b"" if none came)."""
        if self._sock is not None:
            if not select.select([self._sock], [], [], POLL)[0]:
                return b""
            data = self._sock.recv(READ_CHUNK)
            if not data:
                raise ConnectionResetError(104, "Connection closed by the device")
            return data
        data = self.port.read(1)
        if data:
            waiting = self.port.in_waiting
            if waiting:
                data += self.port.read(waiting)
        return data

    def request(self, type: int, payload: bytes = b"", timeout: float | None = None) -> Frame:
        """Send one request and return its reply; DeviceError for an ERROR reply, NoAnswer after ``timeout``."""
        seq = self.next_seq()
        self.send(type, seq, payload)
        wait = self.timeout if timeout is None else timeout
        deadline = time.monotonic() + wait
        while True:
            frame = self.receive(max(0.0, deadline - time.monotonic()))
            if frame is None:
                raise NoAnswer(f"{self.name}: no answer to {p.type_name(type)} within {wait:g} s")
            if frame.seq != seq:
                continue  # stale: a reply to an earlier request, a stream sample, an error about garbage
            if frame.type == MsgType.ERROR:
                code, req = p.unpack_error(frame.payload)
                raise DeviceError(code, req)
            if frame.type == type | p.REPLY:
                return frame

    # --- messages ---------------------------------------------------------------

    def ping(self, data: bytes = b"") -> bytes:
        return self.request(MsgType.PING, data).payload

    def wait_ready(self, limit: float) -> None:
        """PING every PING_EVERY s until one is answered (what reaches a board while it starts is lost, and its
        bootloader may take a second); NoAnswer after ``limit`` s. A running board answers the first at once."""
        deadline = time.monotonic() + limit
        while True:
            left = deadline - time.monotonic()
            try:
                self.request(MsgType.PING, b"ready", timeout=max(0.0, min(PING_EVERY, left)))
                return
            except NoAnswer:
                if time.monotonic() >= deadline:
                    busy = (" (an emulator serves one client at a time: is another program connected to it?)"
                            if self.name.startswith("socket://") else "")
                    raise NoAnswer(f"{self.name}: no answer to PING within {limit:g} s: is the firmware running, "
                                   f"and is this its port?{busy}") from None

    def info(self, refresh: bool = False) -> DeviceInfo:
        if self._info is None or refresh:
            self._info = p.unpack_info(self.request(MsgType.INFO).payload)
        return self._info

    def eval(self, inputs) -> tuple[np.ndarray, np.ndarray]:
        """Status (n,) and outputs (n, n_outputs) of the active calibration for rows of inputs (n, n_inputs)."""
        info = self.info()
        x = np.atleast_2d(np.asarray(inputs, dtype=float))
        if x.ndim != 2 or x.shape[1] != info.n_inputs:
            raise InputError(f"the device takes {info.n_inputs} inputs, got rows of shape {x.shape[1:]}")
        k = p.max_eval_batch(info.n_inputs, info.n_outputs, info.real_size)
        status, outputs = [np.zeros(0, dtype=np.int64)], [np.zeros((0, info.n_outputs))]
        for start in range(0, len(x), k):
            reply = self.request(MsgType.EVAL, p.pack_eval(x[start:start + k], info.real_dtype))
            s, o = p.unpack_eval_reply(reply.payload, info.n_outputs, info.real_dtype)
            if len(s) != len(x[start:start + k]):
                raise p.ProtocolError(ErrorCode.BAD_LENGTH, f"EVAL of {len(x[start:start + k])} vectors "
                                                            f"answered with {len(s)} results")
            status.append(s)
            outputs.append(o)
        return np.concatenate(status), np.vstack(outputs)

    def stream(self, period_ms: int, count: int, timeout: float | None = None,
               arrivals: list[float] | None = None) -> list[p.StreamSample]:
        """Start a stream of ``count`` samples and collect them (NoAnswer when they stop coming).
        ``arrivals``: a list that gets each sample's arrival, in seconds after the request was sent."""
        info = self.info()
        seq = self._seq % 255 + 1
        t0 = time.perf_counter()
        self.request(MsgType.STREAM, p.pack_stream(period_ms, count))
        samples = []
        wait = self.timeout + period_ms / 1000 if timeout is None else timeout
        while len(samples) < count:
            deadline = time.monotonic() + wait
            frame = None
            while frame is None or frame.seq != seq or frame.type != MsgType.STREAM_SAMPLE:
                frame = self.receive(max(0.0, deadline - time.monotonic()))
                if frame is None:
                    raise NoAnswer(f"{self.name}: stream stopped after {len(samples)} of {count} samples")
            if arrivals is not None:
                arrivals.append(time.perf_counter() - t0)
            samples.append(p.unpack_stream_sample(frame.payload, info.n_inputs, info.n_outputs, info.real_dtype))
        return samples

    def stop_stream(self) -> None:
        self.request(MsgType.STREAM, p.pack_stream(0, 0))

    def load_calibration(self, blob: bytes, chunk: int = p.CAL_DATA_MAX) -> str:
        """CAL_BEGIN, CAL_DATA in chunks, CAL_COMMIT; the active model hash the device reports (hex)."""
        if not 1 <= chunk <= p.CAL_DATA_MAX:
            raise InputError(f"chunk must be 1..{p.CAL_DATA_MAX} bytes, got {chunk}")
        blob = bytes(blob)
        self._info = None
        self.request(MsgType.CAL_BEGIN, p.pack_cal_begin(len(blob), p.crc32(blob)))
        for offset in range(0, len(blob), chunk):
            part = blob[offset:offset + chunk]
            reply = self.request(MsgType.CAL_DATA, p.pack_cal_data(offset, part))
            got = reply.payload
            if len(got) != p.CAL_DATA_REPLY.size or p.CAL_DATA_REPLY.unpack(got)[0] != offset + len(part):
                raise p.ProtocolError(ErrorCode.BAD_LENGTH, f"CAL_DATA at {offset}: the device reports "
                                                            f"{reply.payload.hex()} received, "
                                                            f"expected {offset + len(part)}")
        reply = self.request(MsgType.CAL_COMMIT)
        if len(reply.payload) != p.HASH_SIZE:
            raise p.ProtocolError(ErrorCode.BAD_LENGTH, f"CAL_COMMIT reply of {len(reply.payload)} bytes "
                                                        f"(expected a {p.HASH_SIZE}-byte hash)")
        return reply.payload.hex()

    def read_calibration(self, limit: int = 1 << 20) -> bytes:
        """The loaded blob's bytes (DeviceError NO_CAL when none is loaded)."""
        from fitgen.c.calblob import HEADER_SIZE, size_from_header

        out = bytearray(self.request(MsgType.CAL_READ, p.pack_cal_read(0, HEADER_SIZE)).payload)
        try:
            size = size_from_header(bytes(out))
        except InputError:
            size = None  # not a v1 header: read until a short chunk
        while size is None or len(out) < size:
            want = p.CAL_READ_MAX if size is None else min(p.CAL_READ_MAX, size - len(out))
            part = self.request(MsgType.CAL_READ, p.pack_cal_read(len(out), want)).payload
            out += part
            if len(part) < want or len(out) >= limit:
                break
        return bytes(out)

    def cal_capacity(self) -> int:
        """The largest blob the device's calibration store takes (0: none), found by CAL_BEGIN alone: no
        blob byte is sent, the active calibration is untouched (the staging it opens is abandoned)."""
        def takes(size: int) -> bool:
            try:
                self.request(MsgType.CAL_BEGIN, p.pack_cal_begin(size, 0))
            except DeviceError as exc:
                if exc.code in (ErrorCode.BAD_ARG, ErrorCode.CAL_INVALID):
                    return False
                raise
            return True

        lo, hi = 0, p.CAL_MAX_BLOB  # lo: taken (0 trivially), hi + 1: refused
        if takes(hi):
            return hi
        hi -= 1
        while lo < hi:
            mid = (lo + hi + 1) // 2
            lo, hi = (mid, hi) if takes(mid) else (lo, mid - 1)
        return lo

    def reset_calibration(self) -> None:
        self._info = None
        self.request(MsgType.CAL_RESET)

    def bench(self, n: int, timeout: float | None = None) -> p.BenchResult:
        """``n`` estimates timed on the device: (ticks, tick_hz, n)."""
        wait = self.timeout + n * 1e-4 if timeout is None else timeout
        return p.unpack_bench(self.request(MsgType.BENCH, p.pack_bench_request(n), timeout=wait).payload)


class FlashFailed(RuntimeError):
    """The device did not take a calibration blob as it was sent."""


def flash_model(dev: Device, model, origin: str, *, sensor_id: str = "paper", fma: bool = False):
    """Load ``model`` (read from ``origin``) into ``dev`` as a calibration blob and read it back: (blob, the
    device's info, the active model hash it reports). InputError when its build cannot take the model;
    FlashFailed when the blob is refused, read back otherwise, or another model is active."""
    from fitgen.c.calblob import to_blob
    from fitgen.equations.model import check_input_units

    try:
        info = dev.info()
    except (DeviceError, p.ProtocolError) as exc:
        raise InputError(f"{dev.name}: INFO failed: {exc}") from None
    if info.precision == "fixed":
        raise InputError("the device is a fixed-point build; calibration blobs need a float or double build")
    if (info.n_inputs, info.n_outputs) != (model.n_inputs, len(model.equations)):
        n_out = len(model.equations)
        raise InputError(f"model {origin} has {model.n_inputs} inputs and {n_out} output{'s' * (n_out != 1)}; "
                         f"the device's build has {info.n_inputs} and {info.n_outputs}")
    if info.adc_chips:  # its inputs are its ADCs' volts, whatever the blob says
        check_input_units(model, "V", "the device's ADC readings", f"model {origin}")
        check_reported_full_scale(info.adc_chips, model.input_min, model.input_max)
    blob = to_blob(model, info.precision, sensor_id=sensor_id, fma=fma)
    try:
        answer = dev.load_calibration(blob)
        back = dev.read_calibration()
    except DeviceError as exc:
        if exc.code == ErrorCode.BAD_ARG and exc.request_type == MsgType.CAL_BEGIN:
            room = dev.cal_capacity()
            if len(blob) > room:  # the model, not the device, is at fault: bad input, exit status 2
                raise InputError(f"the {len(blob)}-byte blob does not fit the device's {room}-byte calibration store: "
                                  "refused, nothing written; the device keeps the model it runs (fit fewer terms, "
                                  "e.g. fitgen fit --max-terms)") from exc
        raise FlashFailed(f"calibration not loaded: {exc}") from exc
    except p.ProtocolError as exc:
        raise FlashFailed(f"calibration not loaded: {exc}") from exc
    if back != blob:
        first = next((i for i, (a, b) in enumerate(zip(back, blob)) if a != b), min(len(back), len(blob)))
        raise FlashFailed(f"read-back differs from the {len(blob)}-byte blob sent ({len(back)} bytes read, first "
                          f"difference at byte {first})")
    if answer != model.sha256:
        raise FlashFailed(f"the device reports active model {answer}, expected {model.sha256}")
    return blob, info, answer
