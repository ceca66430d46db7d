"""The serial protocol (docs/protocol.md): COBS, frames, payloads, the firmware's proto_defs.h, the Device
client against a fake device, and ``tactile-host flash``."""

from __future__ import annotations

import socket
import struct
import subprocess

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fitgen.base.errors import InputError
from fitgen.base.layout import Layout
from fitgen.c.calblob import to_blob
from fitgen.c.compiled import compile_checked
from host import protocol as p
from host import protocol_c
from host.protocol import ErrorCode, Frame, MsgType, ProtocolError
from host.device import BOOT_WAIT, Device, NoAnswer

from conftest import assert_one_line_error, model_for_sensor, require_tool, run_cli

# --- COBS ---------------------------------------------------------------------------

RUN254 = bytes(range(1, 255))
COBS_VECTORS = [  # Wikipedia's examples (encoded without the delimiter)
    (b"\x00", b"\x01\x01"),
    (b"\x00\x00", b"\x01\x01\x01"),
    (b"\x00\x11\x00", b"\x01\x02\x11\x01"),
    (b"\x11\x22\x00\x33", b"\x03\x11\x22\x02\x33"),
    (b"\x11\x22\x33\x44", b"\x05\x11\x22\x33\x44"),
    (b"\x11\x00\x00\x00", b"\x02\x11\x01\x01\x01"),
    (RUN254, b"\xff" + RUN254),
    (b"\x00" + RUN254, b"\x01\xff" + RUN254),
    (RUN254 + b"\xff", b"\xff" + RUN254 + b"\x02\xff"),
    (bytes(range(2, 256)) + b"\x00", b"\xff" + bytes(range(2, 256)) + b"\x01\x01"),
    (bytes(range(3, 256)) + b"\x00\x01", b"\xfe" + bytes(range(3, 256)) + b"\x02\x01"),
    (b"", b"\x01"),
]


@pytest.mark.parametrize("raw, encoded", COBS_VECTORS)
def test_cobs_known_vectors(raw, encoded):
    assert p.cobs_encode(raw) == encoded
    assert p.cobs_decode(encoded) == raw


@settings(deadline=None)  # a stall of the machine is not a failure
@given(st.binary(max_size=600))
def test_cobs_round_trip(data):
    enc = p.cobs_encode(data)
    assert 0 not in enc
    assert len(enc) <= len(data) + 1 + len(data) // 254
    assert p.cobs_decode(enc) == data


@settings(deadline=None)
@given(st.binary(max_size=600))
def test_cobs_decode_raises_only_protocol_error(data):
    try:
        out = p.cobs_decode(data)
    except ProtocolError as exc:
        assert exc.kind == ErrorCode.BAD_FRAME
    else:
        assert 0 not in data and len(out) <= len(data)


@pytest.mark.parametrize("bad", [b"", b"\x00", b"\x02", b"\x05\x11\x22", b"\x03\x11\x00", b"\x01\x00\x01"])
def test_cobs_decode_rejects_malformed(bad):
    with pytest.raises(ProtocolError):
        p.cobs_decode(bad)


# --- frames -------------------------------------------------------------------------


@settings(deadline=None)
@given(st.integers(0, 255), st.integers(0, 255), st.binary(max_size=p.MAX_PAYLOAD))
def test_frame_round_trip(type_, seq, payload):
    wire = p.encode_frame(type_, seq, payload)
    assert wire.endswith(b"\x00") and 0 not in wire[:-1]
    assert len(wire) - 1 <= p.MAX_ENCODED
    assert p.decode_frame(wire[:-1]) == Frame(type_, seq, payload)


@settings(deadline=None)
@given(st.binary(max_size=300))
def test_decode_frame_raises_only_protocol_error(data):
    try:
        p.decode_frame(data)
    except ProtocolError as exc:
        assert exc.kind in (ErrorCode.BAD_FRAME, ErrorCode.BAD_CRC)


def test_decode_frame_errors():
    body = p.frame_body(MsgType.PING, 3, b"abc")
    assert p.decode_frame(p.cobs_encode(body)) == Frame(1, 3, b"abc")
    with pytest.raises(ProtocolError) as exc:
        p.decode_frame(p.cobs_encode(body[:7]))
    assert exc.value.kind == ErrorCode.BAD_FRAME
    with pytest.raises(ProtocolError) as exc:  # len disagrees
        p.decode_frame(p.cobs_encode(body[:2] + b"\x04\x00" + body[4:]))
    assert exc.value.kind == ErrorCode.BAD_FRAME
    with pytest.raises(ProtocolError) as exc:
        p.decode_frame(p.cobs_encode(p.frame_body(MsgType.PING, 3, b"abc", crc=0x12345678)))
    assert exc.value.kind == ErrorCode.BAD_CRC
    with pytest.raises(ValueError):
        p.encode_frame(1, 1, bytes(p.MAX_PAYLOAD + 1))


def test_frame_reader_splits_streams():
    frames = [Frame(1, i, bytes([i]) * i) for i in range(1, 40)]
    wire = b"\x00".join([b""] + [p.encode_frame(f.type, f.seq, f.payload)[:-1] for f in frames]) + b"\x00\x00"
    assert p.FrameReader().feed(wire) == frames  # concatenated, with empty frames between
    for step in (1, 2, 7, 100):  # in pieces
        r = p.FrameReader()
        got = []
        for i in range(0, len(wire), step):
            got += r.feed(wire[i:i + step])
        assert got == frames and not r.errors and r.pending == 0


def test_frame_reader_drops_oversize_and_resynchronises():
    r = p.FrameReader()
    good = p.encode_frame(2, 9, b"")
    events = list(r.events(b"\x01" * 200))
    assert events == []
    events = list(r.events(b"\x01" * 200 + b"\x01" * 500))  # one OVERSIZE, however long it runs
    assert len(events) == 1 and events[0].kind == ErrorCode.OVERSIZE
    events = list(r.events(b"\x01\x01\x00" + good))  # the end of the long frame, then a good one
    assert events == [Frame(2, 9, b"")]
    # exactly MAX_ENCODED bytes is still a frame (a bad one here), not an oversize one
    events = list(r.events(b"\x01" * p.MAX_ENCODED + b"\x00"))
    assert len(events) == 1 and events[0].kind == ErrorCode.BAD_FRAME
    events = list(r.events(b"\x03\x01\x00" + p.frame_body(1, 1)[:0] + good))
    assert [type(e) for e in events] == [ProtocolError, Frame]


# --- payloads -----------------------------------------------------------------------


def test_payloads():
    assert p.max_eval_batch(8, 5, 8) == 4
    assert p.max_eval_batch(8, 5, 4) == 8
    x = np.arange(16.0).reshape(2, 8) / 3
    for prec, dt in (("double", "<f8"), ("float", "<f4")):
        assert np.array_equal(np.frombuffer(p.pack_eval(x, p.real_dtype(prec)), dt).reshape(2, 8),
                              x.astype(dt))
        reply = p.pack_eval_reply([0, -1], x[:, :5], dt)
        assert len(reply) == 2 * (4 + 5 * np.dtype(dt).itemsize)
        status, out = p.unpack_eval_reply(reply, 5, dt)
        assert status.tolist() == [0, -1] and np.array_equal(out, x[:, :5].astype(dt))
        with pytest.raises(ProtocolError):
            p.unpack_eval_reply(reply[:-1], 5, dt)
        s = p.unpack_stream_sample(p.pack_stream_sample(7, 1234, 3, x[0], x[1, :5], dt), 8, 5, dt)
        assert (s.index, s.time_ms, s.status) == (7, 1234, 3) and np.array_equal(s.outputs, x[1, :5].astype(dt))
    info = p.DeviceInfo(1, "float", 8, 5, 1, 0, 256, "ab" * 32, "paper", "0.1.0")
    raw = p.pack_info(info)
    assert len(raw) == p.INFO_SIZE and raw[40:56] == b"paper" + bytes(11)
    assert p.unpack_info(raw) == info and p.unpack_info(raw).real_size == 4
    with pytest.raises(ProtocolError):
        p.unpack_info(raw[:-1])
    assert p.unpack_bench(struct.pack("<QII", 10**9, 10**6, 100)) == (10**9, 10**6, 100)


def test_records_are_the_documented_layouts():
    assert p.INFO.offsets == {"version": 0, "precision": 1, "n_inputs": 2, "n_outputs": 3, "cal_source": 4,
                              "style": 5, "max_payload": 6, "hash": 8, "sensor_id": 40, "fw_version": 56}
    assert (p.INFO_SIZE, p.HEADER_SIZE, p.SAMPLE.size, p.BENCH_REPLY.offsets["n"], p.CAL_READ.size) == (68, 4, 10, 12, 6)


# --- the firmware's copy: proto_defs.h ------------------------------------------------


def test_proto_defs_h_holds_the_python_numbers(tmp_path):
    """proto_defs.h, compiled warning-free: every constant as host/protocol.py has it."""
    gcc = require_tool("gcc")
    defs = protocol_c.defines()
    expected = {f"PROTO_MSG_{t.name}": int(t) for t in MsgType} | {f"PROTO_{e.name}": int(e) for e in ErrorCode}
    expected |= {"PROTO_REPLY": p.REPLY, "PROTO_MAX_PAYLOAD": p.MAX_PAYLOAD, "PROTO_MAX_BODY": p.MAX_BODY,
                 "PROTO_MAX_ENCODED": p.MAX_ENCODED, "PROTO_CAL_DATA_MAX": p.CAL_DATA_MAX,
                 "PROTO_BENCH_MAX": p.BENCH_MAX, "PROTO_PRECISION_FIXED": p.PRECISIONS.index("fixed")}
    for record, layout in p.LAYOUTS.items():
        expected[f"PROTO_{record}_SIZE"] = layout.size
        expected |= {f"PROTO_{record}_{field.upper()}": at for field, at in layout.offsets.items()}
    assert expected.items() <= defs.items()
    (tmp_path / "proto_defs.h").write_text(protocol_c.render_proto_defs())
    lines = "".join(f'    printf("{name} %lu\\n", (unsigned long){name});\n' for name in defs)
    (tmp_path / "defs.c").write_text(f'#include <stdio.h>\n#include "proto_defs.h"\nint main(void)\n{{\n{lines}'
                                     "    return 0;\n}\n")
    compile_checked(gcc, [tmp_path / "defs.c"], tmp_path / "defs", tmp_path)
    out = subprocess.run([str(tmp_path / "defs")], capture_output=True, text=True, check=True).stdout
    assert {name: int(v) for name, v in (ln.split() for ln in out.splitlines())} == defs


def test_proto_defs_h_refuses_a_name_twice(monkeypatch):
    monkeypatch.setitem(p.LAYOUTS, "CAL", Layout(("data_max", "H")))  # PROTO_CAL_DATA_MAX, a limit's name
    with pytest.raises(ValueError, match="PROTO_CAL_DATA_MAX would be defined twice"):
        protocol_c.render_proto_defs()


# --- the Device client against the fake device ------------------------------------


@pytest.fixture(scope="module")
def paper_model():
    from fitgen.fitting.fit import fit_model
    from fitgen.physics.sensor import load_sensor
    from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate

    return fit_model(simulate(load_sensor("paper"), grid_poses(PAPER_GRIDS["paper-sim"])))


@pytest.fixture(scope="module")
def other_model(paper_model):
    """The paper model with other coefficients: a calibration to load."""
    from fitgen.equations.model import Equation, Model

    eqs = tuple(Equation(e.name, e.intercept + 0.5, e.terms, tuple(c * 1.01 for c in e.coefficients))
                for e in paper_model.equations)
    return Model(paper_model.input_min, paper_model.input_max, eqs)


def vectors(model, n=37):
    rng = np.random.default_rng(1)
    x = model.input_min + (model.input_max - model.input_min) * rng.uniform(-0.2, 1.2, (n, model.n_inputs))
    x[3, 2] = np.nan
    return x


@pytest.mark.parametrize("transport", ["pty", "tcp"])
def test_device_ping_info_eval(paper_model, transport):
    from host.device import Device

    from fake_device import FakeDevice

    with FakeDevice(paper_model, "double", transport=transport) as fake, Device.open(fake.url, timeout=2) as dev:
        assert dev.ping(b"hello\x00world") == b"hello\x00world"
        assert dev.ping(bytes(range(256)) * 1) == bytes(range(256))
        info = dev.info()
        assert (info.precision, info.n_inputs, info.n_outputs, info.cal_source) == ("double", 8, 5, 0)
        assert info.model_hash == paper_model.sha256 and info.sensor_id == "paper"
        x = vectors(paper_model)
        status, out = dev.eval(x)
        ref, ref_status = paper_model.predict(x, with_status=True)
        assert np.array_equal(status, ref_status) and status[3] == -1
        assert np.array_equal(out, ref)
        assert sum(f.type == MsgType.EVAL for f in fake.requests) == -(-len(x) // 4)


def test_device_calibration_cycle(paper_model, other_model):
    from fitgen.c.calblob import rounded_model, to_blob
    from host.device import Device, DeviceError

    from fake_device import FakeDevice

    with FakeDevice(paper_model, "float") as fake, Device.open(fake.url, timeout=2) as dev:
        with pytest.raises(DeviceError) as exc:
            dev.read_calibration()
        assert exc.value.code == ErrorCode.NO_CAL and "CAL_READ" in str(exc.value)
        blob = to_blob(other_model, "float", sensor_id="rig-2")
        assert dev.load_calibration(blob, chunk=100) == other_model.sha256
        assert dev.read_calibration() == blob
        info = dev.info()
        assert info.cal_source == 1 and info.model_hash == other_model.sha256 and info.sensor_id == "rig-2"
        x = vectors(paper_model)
        _, out = dev.eval(x)
        x32 = x.astype(np.float32).astype(float)  # as the float wire carries them
        assert np.array_equal(out, rounded_model(other_model, "float").predict(x32).astype(np.float32))
        # a corrupt blob, a double blob and a broken sequence are refused; the loaded one stays
        bad = bytearray(blob)
        bad[100] ^= 4
        for wrong, code in ((bytes(bad), ErrorCode.CAL_CRC), (to_blob(other_model, "double"), ErrorCode.CAL_INVALID)):
            with pytest.raises(DeviceError) as exc:
                dev.load_calibration(wrong)
            assert exc.value.code == code
        with pytest.raises(DeviceError) as exc:
            dev.request(MsgType.CAL_DATA, p.pack_cal_data(0, b"x"))
        assert exc.value.code == ErrorCode.CAL_SEQUENCE
        assert dev.read_calibration() == blob
        dev.reset_calibration()
        assert dev.info().cal_source == 0 and dev.info().model_hash == paper_model.sha256


def test_device_stream_bench_errors(paper_model):
    from host.device import Device, DeviceError

    from fake_device import FakeDevice

    with FakeDevice(paper_model, "double", stale=True) as fake, Device.open(fake.url, timeout=2) as dev:
        samples = dev.stream(5, 6)
        assert [s.index for s in samples] == list(range(6))
        assert all(s.inputs.shape == (8,) and s.outputs.shape == (5,) for s in samples)
        assert np.array_equal(samples[2].outputs, paper_model.predict(samples[2].inputs)[0])
        dev.stop_stream()
        res = dev.bench(100)
        assert res.n == 100 and res.tick_hz == 10**9 and res.ticks > 0
        with pytest.raises(DeviceError) as exc:
            dev.bench(0)
        assert exc.value.code == ErrorCode.BAD_ARG
        with pytest.raises(DeviceError) as exc:
            dev.request(0x42)
        assert exc.value.code == ErrorCode.UNKNOWN_TYPE
        assert dev.reader.errors  # the fake's garbage was seen and skipped
        # garbage on the wire: the device answers with seq 0 and stays in step
        dev.send_raw(b"\x01" * 300 + b"\x00")
        dev.send_raw(p.cobs_encode(p.frame_body(1, 7, b"x", crc=1)) + b"\x00")
        got = [dev.receive(1.0) for _ in range(2)]
        errors = [p.unpack_error(f.payload)[0] for f in got if f.type == MsgType.ERROR and f.seq == 0]
        assert errors == [ErrorCode.OVERSIZE, ErrorCode.BAD_CRC]
        assert dev.ping(b"ok") == b"ok"
        for i in range(300):  # seq wraps past 255, never 0
            assert dev.next_seq() != 0


def test_device_over_a_socket(paper_model):
    """socket:// ports are read directly (pyserial's in_waiting says at most 1 there): whole frames of any
    size, stream samples with their arrival times after the request, and a device that goes away is one
    InputError, not a hang."""
    from host.device import Device, NoAnswer

    from fake_device import FakeDevice

    fake = FakeDevice(paper_model, "double", transport="socket", stale=True)
    with Device.open(fake.url, timeout=2) as dev:
        big = bytes(range(1, 256)) + b"\x00"
        assert dev.ping(big) == big
        arrivals = []
        samples = dev.stream(5, 4, arrivals=arrivals)
        assert [s.index for s in samples] == list(range(4))
        assert len(arrivals) == 4 and 0 < arrivals[0] and all(np.diff(arrivals) > 0)
        fake.close()
        with pytest.raises(InputError, match=fake.url) as exc:
            dev.ping(b"gone")
        assert not isinstance(exc.value, NoAnswer), exc.value


def test_device_no_answer_and_bad_port(paper_model):
    from host.device import Device, NoAnswer

    from fake_device import FakeDevice

    with FakeDevice(paper_model, mute=True) as fake, Device.open(fake.url, timeout=0.2) as dev:
        with pytest.raises(NoAnswer, match="no answer to PING"):
            dev.ping()
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))  # bound, not listening: a connect is refused, and no other program can take it
        port = s.getsockname()[1]
        with pytest.raises(InputError, match=f"cannot open port socket://127.0.0.1:{port}: connection refused"):
            Device.open(f"socket://127.0.0.1:{port}")
    for url in ("/dev/nonexistent-tty", "bogus://x"):
        with pytest.raises(InputError, match="cannot open port"):
            Device.open(url)
    # what the user meant, said: a TCP port without its scheme, a file that is no serial device
    with pytest.raises(InputError, match=r"no such file or directory; a TCP port is given as socket://127\.0\.0\.1:9$"):
        Device.open("127.0.0.1:9")
    with pytest.raises(InputError, match="it is a regular file, not a serial device"):
        Device.open(__file__)


# --- tactile-host flash -------------------------------------------------------------


@pytest.fixture(scope="module")
def paper_model_file(paper_model, tmp_path_factory):
    return str(paper_model.save(tmp_path_factory.mktemp("flash") / "model.json"))


def test_flash_absent_port(paper_model_file):
    proc = run_cli("tactile-host", "flash", "--port", "socket://127.0.0.1:1", paper_model_file)
    assert_one_line_error(proc, 2, "cannot open port socket://127.0.0.1:1")
    for url in ("socket://127.0.0.1", "socket://127.0.0.1:99999"):  # pyserial's own words were a TypeError's
        assert_one_line_error(run_cli("tactile-host", "flash", "--port", url, paper_model_file), 2,
                              "expected HOST:PORT after the scheme, a port from 1 to 65535")
    assert_one_line_error(run_cli("tactile-host", "flash", "--port", "socket://127.0.0.1:1", "--timeout", "1e300",
                                  paper_model_file), 2, "--timeout must be at most 3600")


@pytest.mark.parametrize("precision", ["double", "float"])
def test_flash_loads_and_reads_back(paper_model, paper_model_file, precision):
    from fake_device import FakeDevice

    with FakeDevice(paper_model, precision, transport="tcp") as fake:
        proc = run_cli("tactile-host", "flash", "--port", fake.url, "--sensor-id", "rig-9", "--fma",
                       paper_model_file)
        assert proc.returncode == 0, proc.stderr
        assert len(proc.stdout.splitlines()) == 1 and paper_model.sha256 in proc.stdout
        assert fake.active is not None and fake.active[1].sensor_id == "rig-9" and fake.active[1].fma
        assert fake.active[1].precision == precision


def test_flash_names_the_unit_a_model_was_fitted_for(paper_model, tmp_path):
    """Without --sensor-id the blob carries the name of the sensor the model's held-out figures are for: a unit
    file's (identify -o unit-042.toml), so a device says which unit's calibration it holds; 'paper' before."""
    from fake_device import FakeDevice

    # a bad id given is said before any port is opened (this one refuses connections)
    assert_one_line_error(run_cli("tactile-host", "flash", "--port", "socket://127.0.0.1:1", "--sensor-id", "capteur-é",
                                  model_for_sensor(paper_model, "paper", tmp_path / "p.json")), contains="sensor id")
    with FakeDevice(paper_model, "double", transport="tcp") as fake:
        proc = run_cli("tactile-host", "flash", "--port", fake.url,
                       model_for_sensor(paper_model, "unit-042", tmp_path / "u42.json"))
        assert proc.returncode == 0, proc.stderr
        assert fake.active[1].sensor_id == "unit-042" and "sensor id 'unit-042'" in proc.stdout
        assert "note" in proc.stderr  # the fake starts with the drawing's id
    # a name no blob carries had been replaced by 'paper': a unit's calibration called the drawing's
    long = model_for_sensor(paper_model, "a-unit-named-at-length", tmp_path / "long.json")
    assert_one_line_error(run_cli("tactile-host", "flash", "--port", "socket://127.0.0.1:1", long), 2,
                          "the model's sensor, 'a-unit-named-at-length', cannot be the calibration's sensor id")
    with FakeDevice(paper_model, "double", transport="tcp") as fake:
        proc = run_cli("tactile-host", "flash", "--port", fake.url, "--sensor-id", "unit-long", long)
        assert proc.returncode == 0 and fake.active[1].sensor_id == "unit-long", proc.stderr
    # over a unit's own calibration, the drawing's model is flashed with a note that it is another sensor's
    with FakeDevice(paper_model, "double", transport="tcp", sensor_id="unit-042") as fake:
        proc = run_cli("tactile-host", "flash", "--port", fake.url,
                       model_for_sensor(paper_model, "paper", tmp_path / "paper.json"))
        assert proc.returncode == 0, proc.stderr
        assert proc.stderr.strip() == ("tactile-host flash: note: the device held a model for sensor 'unit-042' and "
                                       "now holds one for 'paper'; a model fitted for another sensor errs on this "
                                       "unit (if it is the same unit, give --sensor-id)")


def test_a_board_that_restarts_when_its_port_opens_is_waited_for(paper_model, paper_model_file):
    """A board that loses what comes in its first 0.8 s after the port opens (an Uno's bootloader, after the
    reset DTR gives it): a request sent at once goes unanswered, while `tactile-host flash` and
    Device.open(ready=) PING until it answers, and then talk to it."""
    from fake_device import FakeDevice

    with FakeDevice(paper_model, "double", transport="socket", boot=0.8) as fake:
        with Device.open(fake.url, timeout=0.3) as dev:
            with pytest.raises(NoAnswer, match="no answer to INFO within 0.3 s"):
                dev.info()
    with FakeDevice(paper_model, "double", transport="socket", boot=0.8) as fake:
        with Device.open(fake.url, timeout=2, ready=BOOT_WAIT) as dev:
            assert dev.info().n_inputs == paper_model.n_inputs
        pings = [f.seq for f in fake.requests if f.type == MsgType.PING]
        # the first PING, sent at once, was lost in the boot; the fake answered one after it (two if it stalled)
        assert pings and pings[0] > 1 and len(pings) <= 2, pings
    with FakeDevice(paper_model, "double", transport="socket", boot=0.8) as fake:
        proc = run_cli("tactile-host", "flash", "--port", fake.url, "--timeout", "2", paper_model_file)
        assert proc.returncode == 0, proc.stderr
        assert fake.active is not None


def test_flash_failures(paper_model, paper_model_file, model, model_file):
    from fake_device import FakeDevice

    with FakeDevice(paper_model, "double", corrupt_read=True) as fake:
        proc = run_cli("tactile-host", "flash", "--port", fake.url, paper_model_file)
        assert_one_line_error(proc, 1, "read-back differs")
    with FakeDevice(paper_model, "double", capacity=100) as fake:
        proc = run_cli("tactile-host", "flash", "--port", fake.url, paper_model_file)
        # the refusal names the blob's size and the store's, found by CAL_BEGIN alone (nothing written)
        blob = len(to_blob(paper_model, "double"))
        assert_one_line_error(proc, 2, f"the {blob}-byte blob does not fit the device's 100-byte calibration store")
        assert fake.active is None
    # a firmware that reads ADCs takes volts: a model fitted in mT would flash, read back and answer nonsense
    assert paper_model.input_units == "mT"
    with FakeDevice(paper_model, "double", adc_chips=(("ads1115", 0x48, 4, 1, 4, 0),) * 2) as fake:
        proc = run_cli("tactile-host", "flash", "--port", fake.url, paper_model_file)
        assert_one_line_error(proc, 2, "takes inputs in mT; the device's ADC readings are in V")
        assert fake.active is None
    # a build whose PGA the model's readings pass: flashed, its readings would clip and every estimate with them
    assert model.input_units == "V" and 2.048 < model.input_max.max() < 4.096
    for pga, refused in ((2, True), (1, False)):  # codes of 2.048 and 4.096 V
        with FakeDevice(model, "double", adc_chips=(("ads1115", 0x48, 4, pga, 4, 0),) * 2) as fake:
            proc = run_cli("tactile-host", "flash", "--port", fake.url, model_file)
            if refused:
                assert_one_line_error(proc, 2, "beyond its ADC's full scale 2.048 V (ads1115@0x48, the build's PGA "
                                               "2.048 V): its readings would clip; rebuild the firmware with a larger "
                                               "--pga")
                assert fake.active is None
            else:
                assert proc.returncode == 0, proc.stderr
                assert fake.active is not None
    # an ADS7828's reference is not in INFO: its elements are not refused for it
    with FakeDevice(model, "double", adc_chips=(("ads7828", 0x4a, 8, 0, 0, 0),)) as fake:
        assert run_cli("tactile-host", "flash", "--port", fake.url, model_file).returncode == 0
    with FakeDevice(paper_model, "fixed") as fake:
        proc = run_cli("tactile-host", "flash", "--port", fake.url, paper_model_file)
        assert_one_line_error(proc, 2, "fixed-point build")
    with FakeDevice(paper_model, mute=True) as fake:
        proc = run_cli("tactile-host", "flash", "--port", fake.url, "--timeout", "0.3", paper_model_file)
        assert_one_line_error(proc, 2, f"no answer to PING within {BOOT_WAIT:g} s: is the firmware running")
        assert "one client at a time" not in proc.stderr  # a serial port: no emulator to share
        # a longer --timeout is the first PING's too (it waited BOOT_WAIT whatever --timeout said)
        proc = run_cli("tactile-host", "flash", "--port", fake.url, "--timeout", "4", paper_model_file)
        assert_one_line_error(proc, 2, "no answer to PING within 4 s: is the firmware running")
    with FakeDevice(paper_model, mute=True, transport="socket") as fake:  # as QEMU with another client connected
        proc = run_cli("tactile-host", "flash", "--port", fake.url, "--timeout", "0.3", paper_model_file)
        assert_one_line_error(proc, 2, "is this its port? (an emulator serves one client at a time: is another "
                                       "program connected to it?)")
    proc = run_cli("tactile-host", "flash", "--port", "socket://127.0.0.1:1", "--sensor-id", "é", paper_model_file)
    assert proc.returncode == 2
