"""The firmware's C under checkers nobody here wrote: clang's AddressSanitizer, UndefinedBehaviorSanitizer and
MemorySanitizer, and libFuzzer. The I2C bridge reads answers from outside the firmware: a ten-digit errno
overflowed an int, and an answer of "OK" to a read was taken from the stack's bytes past the line."""

import shlex
import subprocess
from pathlib import Path

import numpy as np
from conftest import TWO_CHIPS, require_tool, sim_bus

FIRMWARE = Path(__file__).resolve().parent.parent / "firmware_templates" / "firmware"
HARNESS = Path(__file__).resolve().parent / "c" / "fuzz_bridge.c"
SANITIZE = "-fsanitize=address,undefined,float-cast-overflow -fno-sanitize-recover=all -fno-omit-frame-pointer"

# op (0 write, 1 read, 2 write then read), bytes written and read (mod 34), then the peer's answer line
SEEDS = {
    "read_ok": b"\x01\x00\x02OK 12ab\n",
    "write_ok": b"\x00\x03\x00OK\n",
    "errno": b"\x00\x05\x14E 121\n",
    "errno_past_int": b"\x00\x05\x14E 99999999999\n",  # an int's overflow, in the shipped bridge
    "ok_without_bytes": b"\x01\x00\x02OK\n",  # two bytes "read" from the stack past the line
    "ok_without_space": b"\x01\x00\x02OK&12ab\n",  # taken as OK with its bytes
    "bare_e": b"\x00\x07\x03E\n",  # its errno read past the line
    "clock": b"\x03\x00\x00OK 123456789\n",
    "clock_past_uint64": b"\x03\x00\x00OK 99999999999999999999999\n",
    "silent": b"\x02\x04\x04",
}


def _fuzz(tmp_path, sanitizers: str, runs: int) -> None:
    """The harness built with ``sanitizers`` and libFuzzer, run ``runs`` times from SEEDS, finds nothing."""
    clang = require_tool("clang")
    binary = tmp_path / "fuzz_bridge"
    build = subprocess.run([clang, *shlex.split(sanitizers), "-g", "-O1", "-std=c99", "-Wall", "-Wextra", "-Werror",
                            "-I", str(FIRMWARE), str(HARNESS), "-o", str(binary)], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr
    corpus = tmp_path / "corpus"
    corpus.mkdir()
    for name, data in SEEDS.items():
        (corpus / name).write_bytes(data)
    proc = subprocess.run([str(binary), f"-runs={runs}", "-seed=1", "-max_total_time=60", "-max_len=256",
                           f"-artifact_prefix={tmp_path}/", str(corpus)], capture_output=True, text=True, timeout=300)
    crashes = sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(("crash-", "leak-", "timeout-")))
    assert proc.returncode == 0 and not crashes, (crashes, proc.stderr[-3000:])
    assert "Done " in proc.stderr, proc.stderr[-2000:]  # -max_total_time may end a slow machine's run sooner


def test_the_bridge_under_libfuzzer_with_asan_and_ubsan(tmp_path):
    """Two million answers (a few seconds): no overflow, no read out of bounds, and every transfer's result is
    what its answer says (the harness aborts otherwise)."""
    _fuzz(tmp_path, "-fsanitize=fuzzer " + SANITIZE, 2_000_000)  # clang adds up its -fsanitize= lists


def test_the_bridge_under_libfuzzer_with_msan(tmp_path):
    """MemorySanitizer sees what ASan cannot: a read of the answer buffer's bytes past the line, inside it."""
    _fuzz(tmp_path, "-fsanitize=fuzzer,memory -fno-sanitize-recover=all", 500_000)


def _malformed_peer(line, bus, clock):
    """A bridge peer (host.pi.StandIn) that answers every bus transfer with ``line``."""
    from host.pi import StandIn

    class Malformed(StandIn):
        def answer(self, request):
            return line if request.startswith("R") else super().answer(request)

    return Malformed(bus, clock)


def _sanitized_firmware(model, folder, cmap):
    from hil.firmware import build_firmware, render_firmware

    render_firmware(model, folder, precision="float", style="table", port="posix", cmap=cmap)
    return build_firmware(folder, "posix", cc=f"{require_tool('clang')} {SANITIZE} -g")


def test_the_host_firmware_with_its_adcs_under_asan_and_ubsan(device_model, tmp_path, monkeypatch):
    """The reference firmware built with clang's sanitizers: the HIL suite (EVAL against Python, flashing,
    corrupt blobs, fuzz frames) over a bus that NACKs and times out, then a bridge peer whose answers are
    malformed. The firmware stays up, flags the failed reads, and no sanitizer writes a report."""
    from hil.emulate import HostFirmware
    from hil.suite import READ_FAILED, run_suite
    from host.device import Device
    from host.pi import StandIn

    logs = tmp_path / "logs"
    logs.mkdir()
    monkeypatch.setenv("ASAN_OPTIONS", f"log_path={logs}/asan:detect_leaks=1")
    monkeypatch.setenv("UBSAN_OPTIONS", f"log_path={logs}/ubsan:halt_on_error=1:print_stacktrace=1")
    cmap, bus, clock = sim_bus(TWO_CHIPS, [dict(kind="nack", rate=0.3), dict(kind="timeout", rate=0.1)])
    image = _sanitized_firmware(device_model, tmp_path / "fw", cmap)
    with HostFirmware(image, bridge=StandIn(bus, clock)) as fw:
        with Device.open(fw.url, timeout=10) as dev:
            res = run_suite(dev, device_model, url=fw.url, n_vectors=300, n_fuzz=2000, verbose=False)
    assert res.ok, res.table()
    for line in ("E 99999999999", "OK", "OK&1234", "E", ""):
        cmap, bus, clock = sim_bus(TWO_CHIPS)
        with HostFirmware(image, bridge=_malformed_peer(line, bus, clock)) as fw:
            with Device.open(fw.url, timeout=10) as dev:
                samples = dev.stream(5, 2, timeout=60)
                info = dev.info(refresh=True)
            assert fw.proc.poll() is None, f"the firmware died on {line!r}"
        assert all(s.status & READ_FAILED for s in samples), (line, [hex(s.status) for s in samples])
        assert all(not np.any(np.asarray(s.outputs)) for s in samples)
        assert info.adc_counts["other"] + info.adc_counts["timeout"] > 0, (line, info.adc_counts)
    assert sorted(p.name for p in logs.iterdir()) == [], [p.read_text()[:2000] for p in logs.iterdir()]
