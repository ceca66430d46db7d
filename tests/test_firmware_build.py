"""The reference firmware (firmware_templates/firmware/): rendered deterministically, built warning-free for
the host (gcc) and QEMU's mps2-an386 (arm-none-eabi-gcc), and spoken to over docs/protocol.md: the host
build through pipes and a pty, the Cortex-M4 build in qemu-system-arm through a TCP serial port."""

from __future__ import annotations

import os
import select
import signal
import socket
import struct
import subprocess
import time
import tty

import numpy as np
import pytest

from fitgen.c.calblob import to_blob
from fitgen.base.errors import InputError
from fitgen.fitting.fit import fit_model
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate
from hil.firmware import build_firmware, firmware_size, render_firmware
from host import protocol as P
from fitgen.c.compiled import CompiledModel
from host.protocol import ErrorCode as E
from host.protocol import MsgType as T

from conftest import interrupt_after_rename, require_tool


@pytest.fixture(scope="module")
def paper_model():
    return fit_model(simulate(load_sensor("paper"), grid_poses(PAPER_GRIDS["paper-sim"])))


_BUILDS: dict = {}


def built(model, tmp_path_factory, port: str, precision: str, style: str, fma: bool = False):
    """The firmware of one configuration, built once per test session."""
    key = (port, precision, style, fma)
    if key not in _BUILDS:
        require_tool("gcc" if port == "posix" else "arm-none-eabi-gcc")
        folder = tmp_path_factory.mktemp(f"fw-{port}-{precision}-{style}-{int(fma)}")
        render_firmware(model, folder, precision=precision, style=style, fma=fma, port=port)
        _BUILDS[key] = build_firmware(folder, port)
    return _BUILDS[key]


def test_crc_table_matches_zlib(paper_model, tmp_path_factory):
    """The 16-entry nibble table of proto.c is zlib's CRC-32 (checked through a PING of every byte value)."""
    fw = built(paper_model, tmp_path_factory, "posix", "float", "table")
    data = bytes(range(256))
    proc = subprocess.run([str(fw)], input=P.encode_frame(T.PING, 9, data), capture_output=True, timeout=30)
    reader = P.FrameReader()
    frames = reader.feed(proc.stdout)
    assert frames == [P.Frame(T.PING | P.REPLY, 9, data)] and not reader.errors
    # COBS in its canonical form: a body ending in a full 254-byte block gets no empty block after it
    payload = next(bytes([k]) * 250 for k in range(1, 256) if 0 not in P.frame_body(T.PING | P.REPLY, 9, bytes([k]) * 250)[-4:])
    proc = subprocess.run([str(fw)], input=P.encode_frame(T.PING, 9, payload), capture_output=True, timeout=30)
    assert proc.stdout == P.encode_frame(T.PING | P.REPLY, 9, payload)


# --- rendering and building -------------------------------------------------------------


def test_render_is_deterministic(paper_model, tmp_path):
    a = render_firmware(paper_model, tmp_path / "a", precision="double", style="unrolled", port="posix")
    b = render_firmware(paper_model, tmp_path / "b", precision="double", style="unrolled", port="posix")
    render_firmware(paper_model, a, precision="double", style="unrolled", port="posix")  # again, in place
    names = sorted(p.name for p in a.iterdir())
    assert names == sorted(p.name for p in b.iterdir())
    assert {"tm_model.h", "main.c", "device.c", "cal.c", "proto.c", "hal_posix.c"} <= set(names)
    for name in names:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    assert paper_model.sha256[:16] in (a / "main.c").read_text()


def test_a_ctrl_c_during_a_render_over_the_last_build_leaves_one_models_sources(paper_model, tmp_path, monkeypatch):
    """tactile-hil emulate --build-dir renders over the last build: a signal between two files left the new model's
    header beside the old main.c (another model's hash) and the old image."""
    from dataclasses import replace

    require_tool("gcc")
    folder = render_firmware(paper_model, tmp_path / "fw", port="posix")
    build_firmware(folder, "posix")
    other = replace(paper_model, input_min=paper_model.input_min * 0.99)
    renamed = interrupt_after_rename(monkeypatch)
    with pytest.raises(KeyboardInterrupt):
        render_firmware(other, folder, port="posix")
    monkeypatch.undo()
    assert len(renamed) > 2 and other.sha256 != paper_model.sha256
    assert other.sha256[:16] in (folder / "main.c").read_text() and other.sha256 in (folder / "tm_model.h").read_text()
    assert not (folder / "firmware").exists()  # built from the other model's sources: gone with them
    assert render_firmware(other, tmp_path / "fresh", port="posix") and \
        all((folder / p.name).read_bytes() == p.read_bytes() for p in (tmp_path / "fresh").iterdir())


def test_render_and_build_refuse_bad_arguments(paper_model, tmp_path):
    with pytest.raises(InputError, match="port"):
        render_firmware(paper_model, tmp_path, port="avr")
    with pytest.raises(InputError, match="sensor id"):
        render_firmware(paper_model, tmp_path, sensor_id='a"b')
    with pytest.raises(InputError, match="no rendered"):
        build_firmware(tmp_path / "empty", "posix")
    folder = render_firmware(paper_model, tmp_path / "x", port="posix")
    with pytest.raises(InputError, match="not found"):
        build_firmware(folder, "posix", cc="no-such-compiler-cc")
    (folder / "cal.c").write_text((folder / "cal.c").read_text() + "\nint broken(void) { return }\n")
    require_tool("gcc")
    with pytest.raises(InputError, match="error") as exc:
        build_firmware(folder, "posix")
    assert "\n" not in str(exc.value)


@pytest.mark.parametrize("precision", ["float", "double"])
@pytest.mark.parametrize("style", ["table", "unrolled"])
@pytest.mark.parametrize("port", ["posix", "mps2"])
def test_builds_warning_free(paper_model, tmp_path_factory, port, precision, style):
    fw = built(paper_model, tmp_path_factory, port, precision, style)
    assert fw.is_file()
    if port == "mps2":
        size = firmware_size(fw)
        assert size["flash"] == size["text"] + size["data"] and size["ram"] == size["data"] + size["bss"]
        assert 0 < size["flash"] < 64 * 1024 and size["ram"] < 16 * 1024


@pytest.mark.parametrize("port", ["posix", "mps2"])
def test_builds_with_fma(paper_model, tmp_path_factory, port):
    assert built(paper_model, tmp_path_factory, port, "float", "unrolled", fma=True).is_file()


# --- talking to a device ----------------------------------------------------------------


class Link:
    """Frames over a pair of file descriptors (pipes, a pty, a socket)."""

    def __init__(self, rfd: int, wfd: int):
        self.rfd, self.wfd = rfd, wfd
        self.reader = P.FrameReader()
        self.pending: list = []

    def send_raw(self, data: bytes) -> None:
        view = memoryview(bytes(data))
        while view:
            n = os.write(self.wfd, view)
            view = view[n:]

    def send(self, type: int, seq: int, payload: bytes = b"") -> None:
        self.send_raw(P.encode_frame(type, seq, payload))

    def receive(self, timeout: float = 5.0):
        """The next Frame or ProtocolError the device sent, None after ``timeout`` s."""
        deadline = time.monotonic() + timeout
        while not self.pending:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self.rfd], [], [], left)[0]:
                return None
            data = os.read(self.rfd, 4096)
            if not data:
                return None
            self.pending += list(self.reader.events(data))
        return self.pending.pop(0)

    def request(self, type: int, seq: int, payload: bytes = b"", timeout: float = 5.0) -> P.Frame:
        self.send(type, seq, payload)
        frame = self.receive(timeout)
        assert isinstance(frame, P.Frame), frame
        assert frame.seq == seq, frame
        return frame

    def ok(self, type: int, seq: int, payload: bytes = b"", timeout: float = 5.0) -> bytes:
        frame = self.request(type, seq, payload, timeout)
        assert frame.type == type | P.REPLY, (frame, P.unpack_error(frame.payload) if frame.is_error else "")
        return frame.payload

    def error(self, type: int, seq: int, payload: bytes = b"") -> int:
        frame = self.request(type, seq, payload)
        assert frame.type == T.ERROR, frame
        code, req = P.unpack_error(frame.payload)
        assert req == type
        return code


def vectors_for(model, n: int = 40, seed: int = 1) -> np.ndarray:
    """Inside the domain, past both ends (clamped), and not finite."""
    rng = np.random.default_rng(seed)
    lo, hi = model.input_min, model.input_max
    inside = lo + (hi - lo) * rng.random((n, model.n_inputs))
    outside = lo + (hi - lo) * rng.uniform(-0.5, 1.5, (n // 2, model.n_inputs))
    bad = np.tile((lo + hi) / 2, (3, 1))
    bad[0, 2], bad[1, 0], bad[2, 7] = np.nan, np.inf, -np.inf
    return np.vstack([inside, outside, bad])


def eval_on(link: Link, model, precision: str, x: np.ndarray, seq0: int = 100):
    dtype = P.real_dtype(precision)
    k = P.max_eval_batch(model.n_inputs, len(model.equations), dtype.itemsize)
    status, out = [], []
    for i in range(0, len(x), k):
        reply = link.ok(T.EVAL, (seq0 + i // k) % 255 + 1, P.pack_eval(x[i:i + k], dtype))
        s, o = P.unpack_eval_reply(reply, len(model.equations), dtype)
        status.append(s)
        out.append(o)
    return np.concatenate(status), np.vstack(out)


def load_blob(link: Link, blob: bytes, seq: int = 50) -> bytes:
    link.ok(T.CAL_BEGIN, seq, P.pack_cal_begin(len(blob), P.crc32(blob)))
    for off in range(0, len(blob), P.CAL_DATA_MAX):
        got = link.ok(T.CAL_DATA, seq, P.pack_cal_data(off, blob[off:off + P.CAL_DATA_MAX]))
        assert struct.unpack("<I", got)[0] == min(off + P.CAL_DATA_MAX, len(blob))
    return link.ok(T.CAL_COMMIT, seq)


@pytest.fixture
def posix_device(paper_model, tmp_path_factory, request):
    """A running host build (precision, style from the test's parameters) on pipes."""
    precision, style = request.param
    fw = built(paper_model, tmp_path_factory, "posix", precision, style)
    proc = subprocess.Popen([str(fw)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        yield Link(proc.stdout.fileno(), proc.stdin.fileno()), precision, style
        proc.stdin.close()
        assert proc.wait(timeout=10) == 0  # end of stdin: a clean exit
        assert proc.stderr.read() == b""
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for f in (proc.stdin, proc.stdout, proc.stderr):
            f.close()


BOTH = [("float", "table"), ("double", "unrolled")]


@pytest.mark.parametrize("posix_device", BOTH, indirect=True)
def test_posix_ping_info_eval(paper_model, posix_device):
    link, precision, style = posix_device
    assert link.ok(T.PING, 1, b"hello") == b"hello"
    assert link.ok(T.PING, 2) == b""
    data = bytes(range(256))[::-1]
    assert link.ok(T.PING, 255, data) == data
    info = P.unpack_info(link.ok(T.INFO, 3))
    assert (info.protocol_version, info.precision, info.n_inputs, info.n_outputs) == (1, precision, 8, 5)
    assert (info.cal_source, info.style_name, info.max_payload) == (0, style, 256)
    assert (info.model_hash, info.sensor_id, info.firmware_version) == (paper_model.sha256, "paper", "0.1.0")

    x = vectors_for(paper_model)
    status, out = eval_on(link, paper_model, precision, x)
    with CompiledModel(paper_model, precision, style) as cm:
        ref, ref_status = cm.predict(x)
    assert np.array_equal(status, ref_status)
    assert np.array_equal(out, ref)  # the same header, the same compiler: bit for bit
    assert set(status[:40]) == {0} and np.all(status[40:60] > 0) and list(status[-3:]) == [-1] * 3


@pytest.mark.parametrize("posix_device", BOTH, indirect=True)
def test_posix_errors_and_resync(paper_model, posix_device):
    link, precision, _ = posix_device
    real = P.real_dtype(precision).itemsize
    body = bytearray(P.frame_body(T.PING, 7, b"abc"))
    body[-1] ^= 0x01
    link.send_raw(P.cobs_encode(bytes(body)) + b"\0")
    assert link.receive() == P.Frame(T.ERROR, 0, P.pack_error(E.BAD_CRC, 0))
    link.send_raw(b"\x03\x01\x00")  # decodes to 3 bytes: too short
    assert link.receive() == P.Frame(T.ERROR, 0, P.pack_error(E.BAD_FRAME, 0))
    link.send_raw(P.cobs_encode(P.frame_body(T.PING, 7, b"abc")[:-1] + b"\x01\x02") + b"\0")  # len disagrees
    assert link.receive() == P.Frame(T.ERROR, 0, P.pack_error(E.BAD_FRAME, 0))
    link.send_raw(b"\x00\x00\x00")  # empty frames: ignored
    link.send_raw(b"\x55" * 1000 + b"\x00")
    assert link.receive() == P.Frame(T.ERROR, 0, P.pack_error(E.OVERSIZE, 0))
    link.send_raw(b"\x55" * 20)  # a half frame: the next delimiter resynchronises
    link.send_raw(b"\x00")
    assert link.receive() == P.Frame(T.ERROR, 0, P.pack_error(E.BAD_FRAME, 0))
    assert link.ok(T.PING, 8, b"still here") == b"still here"

    assert link.error(0x42, 9) == E.UNKNOWN_TYPE
    assert link.error(0x81, 9) == E.UNKNOWN_TYPE
    assert link.error(T.INFO, 10, b"x") == E.BAD_LENGTH
    assert link.error(T.EVAL, 11) == E.BAD_LENGTH
    assert link.error(T.EVAL, 11, bytes(8 * real + 1)) == E.BAD_LENGTH
    assert link.error(T.STREAM, 12, b"\0\0\1") == E.BAD_LENGTH
    assert link.error(T.STREAM, 12, P.pack_stream(0, 5)) == E.BAD_ARG
    assert link.error(T.BENCH, 13, struct.pack("<I", 0)) == E.BAD_ARG
    assert link.error(T.BENCH, 13, struct.pack("<I", 1_000_001)) == E.BAD_ARG
    assert link.error(T.CAL_BEGIN, 14, P.pack_cal_begin(1 << 20, 0)) == E.BAD_ARG
    assert link.error(T.CAL_DATA, 15, P.pack_cal_data(0, b"x")) == E.CAL_SEQUENCE
    assert link.error(T.CAL_COMMIT, 16) == E.CAL_SEQUENCE
    assert link.error(T.CAL_READ, 17, P.pack_cal_read(0, 16)) == E.NO_CAL
    bench = P.unpack_bench(link.ok(T.BENCH, 18, struct.pack("<I", 1000)))
    assert bench.n == 1000 and bench.tick_hz == 1_000_000_000 and bench.ticks > 0


@pytest.mark.parametrize("posix_device", [("float", "table"), ("double", "table")], indirect=True)
def test_posix_calibration_blob(paper_model, posix_device):
    """A loaded blob's interpreter answers exactly what the compiled-in table style answers."""
    link, precision, _ = posix_device
    x = vectors_for(paper_model, seed=5)
    compiled = eval_on(link, paper_model, precision, x)
    blob = to_blob(paper_model, precision)
    assert load_blob(link, blob) == bytes.fromhex(paper_model.sha256)
    info = P.unpack_info(link.ok(T.INFO, 60))
    assert info.cal_source == 1 and info.model_hash == paper_model.sha256 and info.sensor_id == "paper"
    loaded = eval_on(link, paper_model, precision, x)
    assert np.array_equal(loaded[0], compiled[0]) and np.array_equal(loaded[1], compiled[1])
    back = b"".join(link.ok(T.CAL_READ, 61, P.pack_cal_read(off, 256)) for off in range(0, len(blob), 256))
    assert back == blob
    assert link.ok(T.CAL_READ, 62, P.pack_cal_read(len(blob) - 3, 256)) == blob[-3:]
    assert link.ok(T.CAL_READ, 62, P.pack_cal_read(len(blob) + 10, 5)) == b""
    assert link.error(T.CAL_READ, 62, P.pack_cal_read(0, 0)) == E.BAD_ARG

    # failures leave the active calibration as it was
    other = "double" if precision == "float" else "float"
    bad = bytearray(blob)
    bad[100] ^= 0x40  # the trailer no longer matches
    fixed_crc = bytearray(b"TMCX" + blob[4:-4])
    fixed_crc += struct.pack("<I", P.crc32(bytes(fixed_crc)))  # a whole blob with a bad magic
    cases = [(to_blob(paper_model, other), E.CAL_INVALID), (bytes(bad), E.CAL_CRC), (bytes(fixed_crc), E.CAL_INVALID)]
    for data, code in cases:
        link.ok(T.CAL_BEGIN, 70, P.pack_cal_begin(len(data), P.crc32(data)))
        for off in range(0, len(data), P.CAL_DATA_MAX):
            link.ok(T.CAL_DATA, 71, P.pack_cal_data(off, data[off:off + P.CAL_DATA_MAX]))
        assert link.error(T.CAL_COMMIT, 72) == code
    link.ok(T.CAL_BEGIN, 73, P.pack_cal_begin(len(blob), P.crc32(blob) ^ 1))
    link.ok(T.CAL_DATA, 74, P.pack_cal_data(0, blob[:10]))
    assert link.error(T.CAL_DATA, 74, P.pack_cal_data(5, blob[:10])) == E.CAL_SEQUENCE
    assert link.error(T.CAL_COMMIT, 75) == E.CAL_SEQUENCE
    assert P.unpack_info(link.ok(T.INFO, 76)).cal_source == 1
    assert link.ok(T.CAL_READ, 77, P.pack_cal_read(0, 64)) == blob[:64]

    link.ok(T.CAL_RESET, 78)
    assert P.unpack_info(link.ok(T.INFO, 79)).cal_source == 0
    assert link.error(T.CAL_READ, 80, P.pack_cal_read(0, 16)) == E.NO_CAL


@pytest.mark.parametrize("posix_device", [("double", "table")], indirect=True)
def test_posix_fma_blob(paper_model, posix_device):
    link, precision, _ = posix_device
    load_blob(link, to_blob(paper_model, precision, fma=True))
    x = vectors_for(paper_model, seed=6)
    status, out = eval_on(link, paper_model, precision, x)
    with CompiledModel(paper_model, precision, "table", fma=True) as cm:
        ref, ref_status = cm.predict(x)
    assert np.array_equal(status, ref_status) and np.array_equal(out, ref)


@pytest.mark.parametrize("precision", ["float", "double"])
def test_posix_built_with_ofast_answers_as_built_with_o2(paper_model, tmp_path_factory, precision):
    """A firmware built with -Ofast (the build's flags file comes after -O2): the header's and cal.c's pragmas
    keep the estimates' bits, -1 for non-finite readings, and the refusal of a blob with a NaN coefficient."""
    folder = tmp_path_factory.mktemp(f"fw-ofast-{precision}")
    render_firmware(paper_model, folder, precision=precision, style="table", port="posix")
    (folder / "build_flags").write_text("-Ofast\n")
    x = vectors_for(paper_model, seed=7)
    blob = to_blob(paper_model, precision)
    real = "<f" if precision == "float" else "<d"
    at = blob.find(struct.pack(real, paper_model.equations[0].intercept))
    assert at > 0
    nan_blob = bytearray(blob[:-4])
    nan_blob[at:at + struct.calcsize(real)] = struct.pack(real, float("nan"))
    nan_blob += struct.pack("<I", P.crc32(bytes(nan_blob)))  # a sound trailer: the check is the interpreter's
    answers = []
    for fw in (built(paper_model, tmp_path_factory, "posix", precision, "table"), build_firmware(folder, "posix")):
        proc = subprocess.Popen([str(fw)], stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        try:
            link = Link(proc.stdout.fileno(), proc.stdin.fileno())
            compiled = eval_on(link, paper_model, precision, x)
            load_blob(link, blob)
            loaded = eval_on(link, paper_model, precision, x)
            link.ok(T.CAL_BEGIN, 90, P.pack_cal_begin(len(nan_blob), P.crc32(bytes(nan_blob))))
            for off in range(0, len(nan_blob), P.CAL_DATA_MAX):
                link.ok(T.CAL_DATA, 91, P.pack_cal_data(off, bytes(nan_blob[off:off + P.CAL_DATA_MAX])))
            assert link.error(T.CAL_COMMIT, 92) == E.CAL_INVALID
            answers.append((compiled, loaded))
        finally:
            proc.kill()
            proc.wait()
            proc.stdin.close()
            proc.stdout.close()
    (o2, o2_blob), (fast, fast_blob) = answers
    assert np.all(o2[0][-3:] == -1) and np.all(o2[1][-3:] == 0)
    for got in (fast, fast_blob, o2_blob):
        assert np.array_equal(got[0], o2[0]) and np.array_equal(got[1], o2[1])


@pytest.mark.parametrize("posix_device", [("float", "unrolled")], indirect=True)
def test_posix_stream(paper_model, posix_device):
    link, precision, style = posix_device
    dtype = P.real_dtype(precision)
    t0 = time.monotonic()
    assert link.ok(T.STREAM, 20, P.pack_stream(20, 4)) == b""
    samples = []
    for _ in range(4):
        f = link.receive()
        assert f.type == T.STREAM_SAMPLE and f.seq == 20
        samples.append(P.unpack_stream_sample(f.payload, 8, 5, dtype))
    assert time.monotonic() - t0 >= 0.07
    assert [s.index for s in samples] == [0, 1, 2, 3]
    times = [s.time_ms for s in samples]
    # on the 20 ms grid: a sample the OS woke late (by less than a period) shortens the gap after it, never
    # two in a row (a burst would); one late by more restarts the grid
    assert all(1 <= b - a <= 1000 for a, b in zip(times, times[1:])), times
    assert all(c - a >= 20 for a, c in zip(times, times[2:])), times
    x = np.array([s.inputs for s in samples])
    assert np.all((x >= paper_model.input_min - 1e-6) & (x <= paper_model.input_max + 1e-6))
    with CompiledModel(paper_model, precision, style) as cm:
        ref, ref_status = cm.predict(x)
    assert np.array_equal(np.array([s.outputs for s in samples]), ref)
    assert [s.status for s in samples] == list(ref_status)
    assert link.receive(0.1) is None  # count reached: the stream ended

    # a new request stops a running stream
    link.ok(T.STREAM, 21, P.pack_stream(5, 60000))
    time.sleep(0.05)
    link.send(T.PING, 22, b"stop")
    while True:
        f = link.receive()
        if f.type != T.STREAM_SAMPLE:
            break
    assert f == P.Frame(T.PING | P.REPLY, 22, b"stop")
    assert link.receive(0.1) is None
    assert link.ok(T.STREAM, 23, P.pack_stream(5, 0)) == b""  # stop with nothing running: an ack


@pytest.mark.parametrize("posix_device", [("double", "table")], indirect=True)
def test_posix_survives_garbage(paper_model, posix_device):
    """Random bytes, then random well-formed frames of every type: one reply each, no hang, no crash."""
    link, _, _ = posix_device
    rng = np.random.default_rng(11)
    link.send_raw(rng.integers(0, 256, 20000, dtype=np.uint8).tobytes() + b"\0")
    link.send(T.PING, 1, b"sync")
    while True:
        f = link.receive()
        assert f is not None
        if isinstance(f, P.Frame) and f.type == T.PING | P.REPLY and f.seq == 1:
            break
    for i in range(300):
        t = int(rng.choice([rng.integers(0, 256), rng.integers(1, 11)]))
        n = int(rng.integers(0, 257)) if rng.random() < 0.5 else int(rng.integers(0, 12))
        payload = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        if t == T.BENCH and n == 4:
            payload = struct.pack("<I", int(rng.integers(1, 5000)))
        seq = i % 255 + 1
        link.send(t, seq, payload)
        while True:
            f = link.receive()
            assert isinstance(f, P.Frame), (t, payload.hex())
            if f.type != T.STREAM_SAMPLE:
                break
        assert f.seq == seq and f.type in (t | P.REPLY, T.ERROR), (t, f)
    assert link.ok(T.PING, 2, b"alive") == b"alive"


def test_posix_pty(paper_model, tmp_path_factory):
    fw = built(paper_model, tmp_path_factory, "posix", "float", "table")
    proc = subprocess.Popen([str(fw), "--pty"], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    fd = None
    try:
        line = proc.stderr.readline()
        assert line.startswith("PTY /dev/"), line
        fd = os.open(line.split(None, 1)[1].strip(), os.O_RDWR | os.O_NOCTTY)
        tty.setraw(fd)
        link = Link(fd, fd)
        assert link.ok(T.PING, 1, b"\0pty\0") == b"\0pty\0"
        assert P.unpack_info(link.ok(T.INFO, 2)).precision == "float"
        os.close(fd)  # the host goes away and comes back: the device keeps serving
        fd = os.open(line.split(None, 1)[1].strip(), os.O_RDWR | os.O_NOCTTY)
        tty.setraw(fd)
        assert Link(fd, fd).ok(T.PING, 3, b"again") == b"again"
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=5) == 0
    finally:
        if fd is not None:
            os.close(fd)
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stderr.close()


# --- the Cortex-M4 build in QEMU --------------------------------------------------------


def test_mps2_in_qemu(paper_model, tmp_path_factory):
    require_tool("qemu-system-arm")
    from hil.emulate import Emulator

    elf = built(paper_model, tmp_path_factory, "mps2", "float", "table")
    # the raw UART, real time; Emulator picks the port again if another program takes it before QEMU binds it
    with Emulator(elf, icount=False, buffered=False) as emu, \
            socket.create_connection(("127.0.0.1", emu.port), timeout=10) as sock:
        link = Link(sock.fileno(), sock.fileno())
        assert link.ok(T.PING, 1, b"m4\0f") == b"m4\0f"
        info = P.unpack_info(link.ok(T.INFO, 2))
        assert (info.precision, info.n_inputs, info.n_outputs, info.style_name) == ("float", 8, 5, "table")
        assert info.model_hash == paper_model.sha256 and info.firmware_version == "0.1.0"

        x = vectors_for(paper_model, n=24, seed=3)
        status, out = eval_on(link, paper_model, "float", x)
        with CompiledModel(paper_model, "float", "table") as cm:
            ref, ref_status = cm.predict(x)
        assert np.array_equal(status, ref_status)
        assert np.all(np.isfinite(out))
        scale = np.max(np.abs(ref), axis=0)
        assert np.all(np.abs(out - ref) <= 1e-4 * scale), np.max(np.abs(out - ref) / scale)

        # the interpreter on the target: the blob answers what the compiled-in table answers
        assert load_blob(link, to_blob(paper_model, "float")) == bytes.fromhex(paper_model.sha256)
        loaded = eval_on(link, paper_model, "float", x)
        assert np.array_equal(loaded[0], status) and np.array_equal(loaded[1], out)

        bench = P.unpack_bench(link.ok(T.BENCH, 3, struct.pack("<I", 200), timeout=10))
        assert bench.n == 200 and bench.tick_hz == 25_000_000 and bench.ticks > 0
        link.send_raw(b"\x55" * 400 + b"\0")
        assert link.receive() == P.Frame(T.ERROR, 0, P.pack_error(E.OVERSIZE, 0))
        assert link.ok(T.PING, 4, b"ok") == b"ok"


# --- fixed point ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def integer_model():
    """A model fixed point can take: volts in (gmr transfer), integer powers only."""
    from fitgen.fitting.fit import FitSettings

    sensor = load_sensor("paper").with_transfer("gmr")
    settings = FitSettings(exponents=("1", "2", "3", "4", "-1", "-2", "-3", "-4"))
    return fit_model(simulate(sensor, grid_poses(PAPER_GRIDS["paper-sim"])), settings=settings)


def test_fixed_point_firmware(integer_model, tmp_path):
    """int32 codes in and out, INFO precision 2, and no calibration blob accepted."""
    require_tool("gcc")
    require_tool("arm-none-eabi-gcc")
    for port in ("posix", "mps2"):
        render_firmware(integer_model, tmp_path / port, precision="fixed", port=port)
        assert build_firmware(tmp_path / port, port).is_file()
    with CompiledModel(integer_model, "fixed") as cm:
        lo, hi = cm.fixed.code_min, cm.fixed.code_max
        rng = np.random.default_rng(2)
        codes = np.vstack([rng.integers(lo, np.asarray(hi) + 1, (6, 8)),
                           rng.integers(np.asarray(lo) - 50, np.asarray(hi) + 50, (6, 8))]).astype(np.int32)
        ref, ref_status = cm.predict_codes(codes)
    fw = tmp_path / "posix" / "firmware"
    req = P.encode_frame(T.INFO, 1) + P.encode_frame(T.CAL_BEGIN, 2, P.pack_cal_begin(100, 0))
    req += b"".join(P.encode_frame(T.EVAL, 3 + i, codes[i:i + 6].tobytes()) for i in (0, 6))
    frames = P.FrameReader().feed(subprocess.run([str(fw)], input=req, capture_output=True, timeout=30).stdout)
    info = P.unpack_info(frames[0].payload)
    assert (info.precision, info.style_name) == ("fixed", "unrolled")
    assert frames[1] == P.Frame(T.ERROR, 2, P.pack_error(E.CAL_INVALID, T.CAL_BEGIN))
    rec = np.frombuffer(frames[2].payload + frames[3].payload, dtype=[("s", "<i4"), ("o", "<i4", (5,))])
    assert np.array_equal(rec["s"], ref_status) and np.array_equal(rec["o"], ref)
