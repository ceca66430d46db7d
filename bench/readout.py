"""Software time per sample of ``tactile-host read``: drivers, estimate and output line, bus access excluded.

Run: ``python bench/readout.py > /tmp/readout.md`` (markdown on stdout; about 15 s), or
``python bench/readout.py --c-only`` for the last table alone (about 10 s). Needs gcc; the last table
(the C drivers) also valgrind, arm-linux-gnueabihf-gcc and qemu-arm (apt: valgrind gcc-arm-linux-gnueabihf
qemu-user); all checked before anything runs. Figures and their reading: docs/readout.md.

The model: fit_model on the paper-sim grid (1,875 poses, no noise) of the ``paper`` sensor
in its ``gmr`` transfer (inputs in V). The channel map: two ADS1115, AIN0-3 single-ended
each, +-4.096 V, 860 SPS, single-shot (the default): 24 transfers a sample (4 rounds x
2 chips x config write, OS poll, result read).

How bus access is taken out. One sample is first read through the simulated bus
(host.simbus.SimBus, the magnet at dx=1 dy=0.5 dz=-1, 0.5 mV noise, a virtual clock) and
every smbus2 call and its answer recorded. A replay bus then answers the same calls from
that record, one ``next()`` on a cycle per call, and the clock is virtual (a sleep only
adds to a number): what is left of a sample is the drivers' Python (building and parsing
bytes, the round schedule, the retry wrapper's fast path), the estimate, and formatting
the CSV line (written to a sink that drops it: the write system call is I/O). The
replay's own time, measured by replaying the record alone (the same calls, in a loop of
``fn(*args)``), is then subtracted; that loop's overhead makes the subtraction slightly
too large, so the software column is, if anything, low by about the loop's cost
(reported beside it). A check pass first confirms that the replay sees exactly the
recorded calls.

Each engine: 300 warm-up samples, then 5,000 samples with perf_counter_ns around each
``Readout.step()``; the median per sample. The replay alone: the same for 5,000 replays.
Components (median of 5,000 calls each): ``AdcArray.read_volts`` on the replay bus,
``engine.estimate``, ``LineFormat.line``.

The second table is not a measurement of hardware: it is the simulated bus's timing model
(datasheet conversion times, 25 us wake-up, 9 clock cycles a byte plus start, repeated
start and stop at the bus clock) for several set-ups, i.e. the time a sample takes on
the wire and in the converters, and the rate that allows.

The third table: what each converter's resolution costs the estimate (the same model
evaluated on the simulated ADC's volts and on the exact volts), and how much one
sample's estimate scatters with the preset's 0.5 mV element noise.
"""

from __future__ import annotations

import itertools
import platform
import statistics
import subprocess
import sys
import time

import numpy as np

from benchutil import need_tools, parse_args
from fitgen.fitting.fit import FitSettings, fit_model
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate
from host.adc import AdcArray
from host.channelmap import Settings, parse_spec
from host.clock import VirtualClock
from host.engine import CEngine, PythonEngine
from host.readout import LineFormat, Readout
from host.simbus import SimBus

SPEC = "ads1115@0x48:0-3,ads1115@0x49:0-3"
POSE = np.array([1.0, 0.5, -1.0, 0.0, 0.0])
CALLS = ("read_i2c_block_data", "write_i2c_block_data", "write_byte", "read_byte", "read_word_data")
N, WARM = 5000, 300


class Recorder:
    """Passes calls to a bus and records (name, args, answer)."""

    def __init__(self, bus):
        self.bus, self.log = bus, []
        for name in CALLS:
            setattr(self, name, self._wrap(name))

    def _wrap(self, name):
        fn = getattr(self.bus, name)

        def call(*args):
            ans = fn(*args)
            self.log.append((name, args, ans))
            return ans
        return call


class ReplayBus:
    """Answers the recorded calls in order, cyclically; ``check`` compares each call with the record."""

    def __init__(self, log, check=False):
        self.log = log
        self._answers = itertools.cycle([a for _, _, a in log])
        self._expect = itertools.cycle([(n, args) for n, args, _ in log])
        for name in CALLS:
            setattr(self, name, self._checked(name) if check else self._fast)

    def _fast(self, *args):
        return next(self._answers)

    def _checked(self, name):
        def call(*args):
            exp = next(self._expect)
            if exp != (name, args):
                raise AssertionError(f"replay saw {(name, args)}, the record has {exp}")
            return next(self._answers)
        return call


class NullSink:
    def write(self, text):
        pass


def median_ns(fn, n=N, warm=WARM) -> float:
    for _ in range(warm):
        fn()
    t = []
    pc = time.perf_counter_ns
    for _ in range(n):
        a = pc()
        fn()
        t.append(pc() - a)
    return statistics.median(t)


def main() -> None:
    sensor = load_sensor("paper").with_transfer("gmr")
    model = fit_model(simulate(sensor, grid_poses(PAPER_GRIDS["paper-sim"])), settings=FitSettings.exact())
    cmap = parse_spec(SPEC)

    # record one sample through the simulated bus
    clock = VirtualClock()
    sim = SimBus.for_channel_map(cmap, sensor, POSE, clock=clock, noise=0.0005)
    rec = Recorder(sim)
    AdcArray(rec, cmap, clock=clock).read_volts()
    log = rec.log
    rec.log = []
    AdcArray(rec, cmap, clock=clock).read_volts()
    assert [(n, a) for n, a, _ in rec.log] == [(n, a) for n, a, _ in log], "the call sequence is not steady"

    # check pass: the replay sees exactly the recorded calls
    chk = AdcArray(ReplayBus(log, check=True), cmap, clock=VirtualClock())
    for _ in range(3):
        chk.read_volts()

    # the replay alone
    replay = ReplayBus(log)
    calls = [(getattr(replay, n), a) for n, a, _ in log]

    def replay_only():
        for fn, args in calls:
            fn(*args)

    def loop_only():
        for fn, args in calls:
            pass

    bus_ns = median_ns(replay_only)
    loop_ns = median_ns(loop_only)

    engines = [PythonEngine(model), CEngine(model), CEngine(model, precision="float")]
    labels = ["python (Model.predict)", "c, double (ctypes)", "c, float (ctypes)"]
    fmt = LineFormat("csv", 8, model.output_names)
    v0 = AdcArray(ReplayBus(log), cmap, clock=VirtualClock()).read_volts()
    rows = []
    for eng, label in zip(engines, labels):
        arr = AdcArray(ReplayBus(log), cmap, clock=VirtualClock())
        reader = Readout(arr, eng, NullSink(), fmt, clock=arr.clock)
        step_ns = median_ns(reader.step)
        drv_ns = median_ns(arr.read_volts)
        est_ns = median_ns(lambda: eng.estimate(v0))
        out, st = eng.estimate(v0)
        fmt_ns = median_ns(lambda: fmt.line(1.7e9, v0, out, st))
        rows.append((label, step_ns, drv_ns, est_ns, fmt_ns))
        print(f"{label}: done", file=sys.stderr)

    gcc = subprocess.run(["gcc", "--version"], capture_output=True, text=True).stdout.splitlines()[0]
    cpu = platform.processor() or platform.machine()
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    print(f"Machine: {cpu}; Python {platform.python_version()}, numpy {np.__version__}, {gcc}.\n")
    print(f"Set-up: {SPEC}, single-shot, 860 SPS; {len(log)} transfers a sample. Replay bus alone: "
          f"{bus_ns / 1e3:.1f} us a sample (of which {loop_ns / 1e3:.1f} us is the replay loop itself).\n")
    print("| engine | sample, replay bus (us) | software, bus excluded (us) | drivers on the replay bus (us) "
          "| estimate (us) | CSV line (us) | target < 100 us |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for label, step_ns, drv_ns, est_ns, fmt_ns in rows:
        sw = (step_ns - bus_ns) / 1e3
        print(f"| {label} | {step_ns / 1e3:.1f} | {sw:.1f} | {drv_ns / 1e3:.1f} | {est_ns / 1e3:.1f} | "
              f"{fmt_ns / 1e3:.1f} | {'yes' if sw < 100 else 'no'} |")
    for eng in engines:
        eng.close()

    print("\nTime on the wire and in the converters per 8-element sample (the simulated bus's timing model, "
          "not a hardware measurement):\n")
    print("| set-up | bus clock | transfers | time per sample (ms) | samples/s at most |")
    print("| --- | --- | --- | --- | --- |")
    setups = [
        (SPEC, Settings(), 100e3), (SPEC, Settings(), 400e3),
        (SPEC, Settings(data_rate=475), 400e3), (SPEC, Settings(data_rate=128), 400e3),
        (SPEC, Settings(mode="continuous"), 400e3),
        ("ads1115@0x48:0-1,ads1115@0x49:0-1,ads1115@0x4a:0-1,ads1115@0x4b:0-1", Settings(), 400e3),
        ("ads7828@0x48", Settings(), 100e3), ("ads7828@0x48", Settings(), 400e3),
    ]
    for spec, settings, hz in setups:
        cm = parse_spec(spec, settings)
        clk = VirtualClock()
        bus = SimBus.for_channel_map(cm, sensor, POSE, clock=clk, bus_hz=hz)
        arr = AdcArray(bus, cm, clock=clk)
        arr.setup()
        arr.read_volts()
        t0, n0 = clk.monotonic(), bus.transfers
        for _ in range(10):
            arr.read_volts()
        dt = (clk.monotonic() - t0) / 10
        chips = spec.split(",")[0].split("@")[0]
        what = f"{len(cm.chips)} x {chips}" + (f", {settings.data_rate} SPS, {settings.mode}" if chips == "ads1115"
                                                else ", 3.3 V reference")
        print(f"| {what} | {hz / 1e3:.0f} kHz | {(bus.transfers - n0) // 10} | {dt * 1e3:.2f} | {1 / dt:.0f} |")

    print("\nWhat the converter costs in accuracy: |estimate through the simulated ADC - estimate from the exact "
          "volts| over 200 random poses (dx, dy in -2..2 mm, dz in -2..0 mm, thx, thy in -5..5 deg; seed 7; "
          "no noise), in mm; and the scatter (standard deviation) of single-sample estimates at dx=1 dy=0.5 dz=-1 "
          "over 200 samples with 0.5 mV rms element noise (the preset's), in mm:\n")
    print("| converter | LSB (mV) | dx max / rms | dy max / rms | dz max / rms | scatter dx, dy, dz at 0.5 mV noise |")
    print("| --- | --- | --- | --- | --- | --- |")
    from fitgen.physics.transfer import readings

    rng = np.random.default_rng(7)
    lo, hi = np.array([-2, -2, -2, -5, -5.0]), np.array([2, 2, 0, 5, 5.0])
    poses = lo + (hi - lo) * rng.random((200, 5))
    exact = model.predict(readings(sensor, poses, adc_bits=0))[:, :3]
    for spec, settings, label, lsb in [
        (SPEC, Settings(), "2 x ADS1115, +-4.096 V", 4.096 / 32768),
        (SPEC, Settings(pga=6.144), "2 x ADS1115, +-6.144 V", 6.144 / 32768),
        ("ads7828@0x48", Settings(), "ADS7828, 3.3 V external reference", 3.3 / 4096),
    ]:
        cm = parse_spec(spec, settings)
        clk = VirtualClock()
        bus = SimBus.for_channel_map(cm, sensor, poses[0], clock=clk)
        arr = AdcArray(bus, cm, clock=clk)
        est = []
        for p in poses:
            bus.set_pose(p)
            est.append(model.predict(arr.read_volts())[0, :3])
        d = np.abs(np.array(est) - exact)
        bus = SimBus.for_channel_map(cm, sensor, POSE, clock=clk, noise=0.0005)
        arr = AdcArray(bus, cm, clock=clk)
        scatter = np.array([model.predict(arr.read_volts())[0, :3] for _ in range(200)]).std(axis=0)
        cells = " | ".join(f"{d[:, j].max():.3f} / {np.sqrt(np.mean(d[:, j] ** 2)):.3f}" for j in range(3))
        print(f"| {label} | {lsb * 1e3:.3f} | {cells} | {', '.join(f'{x:.3f}' for x in scatter)} |")
    cf = CEngine(model, precision="float")
    exact_v = readings(sensor, poses, adc_bits=0)
    diff = np.array([np.abs(cf.estimate(v)[0] - model.predict(v)[0]) for v in exact_v]).max(axis=0)
    cf.close()
    print("\nThe float C engine against Python (double) on the exact volts of the same 200 poses, largest "
          "difference: " + ", ".join(f"{o} {x:.2g}" for o, x in zip(model.output_names, diff)) + " (mm, deg).")
    tr = model.fit_info["outputs"]
    print("\nThe model's own training error (max / rms, mm): " + "; ".join(
        f"{o} {tr[o]['model_training_error']['max']:.3f} / {tr[o]['model_training_error']['rms']:.3f}"
        for o in ("dx", "dy", "dz")) + ".")
    c_drivers_table(model, sensor)


# --- the C drivers (firmware_templates/firmware/adc.c) as tm_pi runs them -------------------------------

C_REPLAY = r"""
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "adc.h"
#include "adc_map.h"
#include "replay.h"
#define TM_API static __attribute__((noinline, noclone))
#include "tm_model.h"
#include <math.h>
#include "pi_options.h"
#include "autozero.h"

static unsigned pos;
static uint64_t t_ns;

/* the recorded answer of the next transfer, in order, cyclically (check: the request must match) */
static int next(uint8_t addr, const uint8_t *wr, uint16_t nw, uint8_t *rd, uint16_t nr)
{
    const replay_rec *r = &REPLAY[pos];
    pos = (pos + 1u) % REPLAY_N;
#ifdef REPLAY_CHECK
    if (r->addr != addr || r->nw != nw || r->nr != nr || memcmp(r->wr, wr, nw) != 0) {
        fprintf(stderr, "replay mismatch at %u\n", pos);
        exit(3);
    }
#else
    (void)addr; (void)wr; (void)nw;
#endif
    memcpy(rd, r->rd, nr);
    return 0;
}
static int w(void *c, uint8_t a, const uint8_t *d, uint16_t n) { (void)c; return next(a, d, n, NULL, 0); }
static int r_(void *c, uint8_t a, uint8_t *d, uint16_t n) { (void)c; return next(a, NULL, 0, d, n); }
static int wr(void *c, uint8_t a, const uint8_t *x, uint16_t nx, uint8_t *y, uint16_t ny)
{
    (void)c;
    return next(a, x, nx, y, ny);
}
static uint64_t now(void *c) { (void)c; return t_ns; }
static void nap(void *c, uint64_t ns) { (void)c; t_ns += ns; }

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

int main(int argc, char **argv)
{
    static const adc_i2c bus = { 0, w, r_, wr, now, nap };
    adc_array a;
    double lsb[TM_N_INPUTS];
    volatile double sink = 0;
    const int bus_only = argc > 1 && strcmp(argv[1], "bus") == 0;
    const int with_az = argc > 1 && strcmp(argv[1], "az") == 0; /* tm_pi --auto-zero */
    static az_state az;
    double zero0[TM_N_INPUTS] = {0}, comp[TM_N_INPUTS], shift[TM_N_INPUTS];
    const long n = argc > 2 ? atol(argv[2]) : 1000;
    const int timed = argc > 3;
    long i;
    unsigned k;
    double t0;
    if (adc_init(&a, &bus, ADC_MAP, ADC_MAP_N_CHIPS, adc_default_policy()) != ADC_OK) {
        return 2;
    }
    for (k = 0; k < TM_N_INPUTS; ++k) {
        lsb[k] = adc_lsb_volts(&ADC_MAP[0]);
    }
    /* a noise floor of 1 V, a band of 1e6 and a hold of 1e9 s: once the window is full every sample runs all of
     * its tests and none moves the zero, auto-zero's most work a sample */
    az_init(&az, zero0, 1.0, 1e6, 1e6, 1e9);
    t0 = now_s();
    for (i = 0; i < n; ++i) {
        if (bus_only) {
            /* the replay alone: the same transfers' answers, no driver logic */
            uint8_t buf[4];
            for (k = 0; k < REPLAY_N; ++k) {
                next(REPLAY[k].addr, REPLAY[k].wr, REPLAY[k].nw, buf, REPLAY[k].nr);
            }
            sink = sink + buf[0];
        } else {
            int32_t codes[TM_N_INPUTS];
            tm_real in[TM_N_INPUTS], out[TM_N_OUTPUTS];
            if (adc_read_codes(&a, codes) != ADC_OK) {
                return 3;
            }
            for (k = 0; k < TM_N_INPUTS; ++k) {
                comp[k] = (double)codes[k] * lsb[k];
                in[k] = (tm_real)(comp[k] - (with_az ? az.zero[k] : 0.0));
            }
            tm_estimate(in, out);
            if (with_az) {
                sink = sink + az_observe(&az, (double)i, comp, out, 0, shift);
            }
            sink = sink + (double)out[0];
        }
    }
    if (timed) {
        printf("%.1f\n", (now_s() - t0) / (double)n * 1e9);
    }
    return sink == 12345.678 ? 1 : 0;
}
"""


class Recording:
    """Passes the C drivers' smbus2 calls to a bus and records each transfer (addr, written, answer)."""

    def __init__(self, bus):
        self.bus, self.log, self.on = bus, [], False

    def read_i2c_block_data(self, addr, reg, n):
        ans = self.bus.read_i2c_block_data(addr, reg, n)
        if self.on:
            self.log.append((addr, [reg], list(ans)))
        return ans

    def write_i2c_block_data(self, addr, reg, data):
        self.bus.write_i2c_block_data(addr, reg, data)
        if self.on:
            self.log.append((addr, [reg] + list(data), []))

    def write_byte(self, addr, value):
        self.bus.write_byte(addr, value)
        if self.on:
            self.log.append((addr, [value], []))


def _replay_header(log) -> str:
    rows = []
    for addr, wr_bytes, rd in log:
        wr = ", ".join(str(b) for b in (wr_bytes + [0] * 4)[:4])
        rd_ = ", ".join(str(b) for b in (rd + [0] * 4)[:4])
        rows.append(f"    {{ {addr}, {len(wr_bytes)}, {len(rd)}, {{ {wr} }}, {{ {rd_} }} }}")
    return ("typedef struct { uint8_t addr, nw, nr; uint8_t wr[4]; uint8_t rd[4]; } replay_rec;\n"
            f"#define REPLAY_N {len(log)}u\n"
            "static const replay_rec REPLAY[REPLAY_N] = {\n" + ",\n".join(rows) + "\n};\n")


def _callgrind_ir(binary, args) -> int:
    out = subprocess.run(["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null", str(binary), *args],
                         capture_output=True, text=True)
    line = next(ln for ln in out.stderr.splitlines() if "Collected" in ln)
    return int(line.split(":")[-1].replace(",", "").strip())


def _qemu_instructions(binary, args, work) -> int:
    log = work / "exec.log"
    subprocess.run(["qemu-arm", "-singlestep", "-d", "nochain,exec", "-D", str(log), str(binary), *args],
                   capture_output=True, check=False)
    with open(log, "rb") as f:
        n = sum(chunk.count(b"\nTrace") for chunk in iter(lambda: f.read(1 << 20), b""))
    log.unlink()
    return n


def c_drivers_table(model, sensor) -> None:
    """Software per sample of tm_pi's loop (the C drivers through the channel map, the volts, the float
    estimate), bus access excluded: x86-64 time and instructions, ARM instructions under qemu-arm."""
    import tempfile
    from pathlib import Path

    from fitgen.physics.transfer import readings
    from host.cdrivers import CAdcArray
    from host.pi import render_pi

    cm = parse_spec(SPEC)
    clk = VirtualClock()
    rec = Recording(SimBus.for_channel_map(cm, sensor, POSE, clock=clk, noise=0.0005))
    arr = CAdcArray(rec, cm, clock=clk)
    arr.probe()
    arr.setup()
    arr.read_codes()
    rec.on = True
    arr.read_codes()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        rest = (readings(sensor, np.zeros((1, 5)))[0], sensor.name)  # tm_pi --auto-zero needs rest readings
        render_pi(model, cm, work, precision="float", rest=rest)
        (work / "replay.h").write_text(_replay_header(rec.log))
        (work / "bench.c").write_text(C_REPLAY)
        flags = ["-std=c99", "-O2", "-I", str(work), str(work / "bench.c"), str(work / "adc.c"), "-lm"]
        subprocess.run(["gcc", *flags, "-DREPLAY_CHECK", "-o", str(work / "check")], check=True)
        for mode in ("full", "az"):
            if subprocess.run([str(work / "check"), mode, "100"]).returncode != 0:
                raise SystemExit("the C replay does not see the recorded transfers")
        subprocess.run(["gcc", *flags, "-o", str(work / "x86")], check=True)
        subprocess.run(["arm-linux-gnueabihf-gcc", "-static", *flags, "-o", str(work / "arm")], check=True)
        n1, n2 = 200, 2200
        modes = ("full", "az", "bus")
        ns = {m: statistics.median(float(subprocess.run([str(work / "x86"), m, "200000", "t"], capture_output=True,
                                                        text=True).stdout) for _ in range(5)) for m in modes}
        # past the window's first 64 samples in both counts: auto-zero's full window, each sample
        ir = {m: (_callgrind_ir(work / "x86", [m, str(n2)]) - _callgrind_ir(work / "x86", [m, str(n1)])) / (n2 - n1)
              for m in modes}
        q1, q2 = 80, 180
        arm = {m: (_qemu_instructions(work / "arm", [m, str(q2)], work)
                   - _qemu_instructions(work / "arm", [m, str(q1)], work)) / (q2 - q1) for m in modes}
    print(f"\nThe C drivers (tm_pi's loop: firmware_templates/firmware/adc.c through the channel map, code x LSB, "
          f"the float estimate), one 8-element sample from the same record ({len(rec.log)} transfers), replayed "
          "in C on a virtual clock; the replay's own cost subtracted:\n")
    print("| where | sample, replay bus | replay alone | software, bus excluded | with --auto-zero (its share) |")
    print("| --- | --- | --- | --- | --- |")
    for where, got, unit in (("x86-64, time (median of 5 runs of 200,000)", ns, " ns"),
                             ("x86-64, instructions (callgrind)", ir, ""),
                             ("ARMv7 Linux (qemu-arm), instructions", arm, "")):
        print(f"| {where} | {got['full']:.0f}{unit} | {got['bus']:.0f}{unit} | {got['full'] - got['bus']:.0f}{unit} | "
              f"{got['az'] - got['bus']:.0f}{unit} ({got['az'] - got['full']:.0f}{unit}) |")


if __name__ == "__main__":
    _args = parse_args(__doc__, lambda ap: ap.add_argument(
        "--c-only", action="store_true", help="only the last table, the C drivers (about 10 s)"))
    need_tools("gcc", "valgrind", "arm-linux-gnueabihf-gcc", "qemu-arm")  # every run ends with the C drivers' table
    if _args.c_only:
        _sensor = load_sensor("paper").with_transfer("gmr")
        c_drivers_table(fit_model(simulate(_sensor, grid_poses(PAPER_GRIDS["paper-sim"])),
                                  settings=FitSettings.exact()), _sensor)
    else:
        main()
