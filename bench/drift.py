"""Drift at rest: a temperature ramp and creep, with and without auto-zero and temperature compensation.

Run:

    python bench/drift.py > out.md            # about 7 minutes on 2 cores; progress on stderr
    python bench/drift.py --plot docs/img     # also docs/img/drift.png

Set-up (deterministic; the simulated bus on a virtual clock, so time is compressed):

- sensor `paper` in its gmr transfer (volts), two ADS1115 at 860 SPS, the sensor's noise
  (0.5 mV rms), a thermistor (10 k NTC, beta 3950) on a third ADS1115;
- model: `fit_model` on the paper-sim grid in volts (the default settings), the family chosen as
  `fitgen fit` chooses it (`auto`);
- drift (host.simsensor.Drift.typical, seed 0): offsets about 1 mV/degC and gains -0.1 %/degC per
  element, temperature ramping 25 -> 30 degC over the run's first 240 s, creep of about 2 mV
  per element with a 120 s time constant;
- temperature compensation: fitted from a simulated `capture --temperature 20,25,30` of 3 poses
  (the drift's coefficients, no ramp, no creep), as `tactile-host capture` does;
- the run: tare at t = 0, then 300 s at 50 samples/s; the magnet rests except for three presses
  (dz = -1 mm, thx = 2 deg) at 60-70 s, 150-165 s and 240-250 s;
- flows: `noise only` (no drift: the reference), `tare only`, `auto-zero`, `temperature
  compensation`, `both`.

Measured: at rest (the true pose 0, from 2 s after a press ends), RMS and max of each estimate,
and the worst output's RMS over the `noise only` flow's; during presses (from 1 s after a press
starts to its end), the mean dz estimate, and any auto-zero update that fell inside a press.

Second table, auto-zero's rest test on models whose single estimates at rest scatter: the same run
(drift, presses; no compensation) with auto-zero testing every sample against the rest band
(`before`, the rule until the window's mean was tested: `AutoZeroSettings(test="sample")`, as replay
zeroes a run recorded then) and testing the window's mean, centred and widened as `tactile-host
read` builds it (`now`, `AutoZero.for_model`), against `tare only`. Models: the default fit above;
the paper's procedure (`--noise 0`) on the drawing; and unit 7 of the drawing (`fitgen simulate
--unit 7`) read through its own equations (fitted as `fitgen fit` fits them, on the unit's own
simulation: the twin of an exact identification).
"""

from __future__ import annotations

import io
import tempfile
from pathlib import Path

import numpy as np

from benchutil import fmt, log, parser, table

from fitgen.base.errors import InputError
from fitgen.base.fileio import make_folder, write_in_folder
from fitgen.fitting.fit import FitSettings, fit_model
from fitgen.fitting.family import fit_auto
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import DEFAULT_RANGES, PAPER_GRIDS, grid_poses, random_poses, simulate
from fitgen.physics.transfer import readings
from fitgen.physics.units import draw_unit
from host.adc import AdcArray
from host.autozero import AutoZero, AutoZeroSettings
from host.capture import Schedule, capture
from host.channelmap import parse_spec
from host.clock import VirtualClock
from host.engine import PythonEngine
from host.readout import Corrections, LineFormat, Readout
from host.rest import rest_reference, tare
from host.simbus import SimBus
from host.simsensor import Drift
from host.temperature import Thermometer, fit_tempcomp, parse_temperature_input

ADC = "ads1115@0x48:0-3,ads1115@0x49:0-3"
THERMISTOR = "ads1115@0x4a:0"
RATE = 50.0
DURATION = 300.0
PRESSES = ((60.0, 70.0), (150.0, 165.0), (240.0, 250.0))
PRESS_POSE = np.array([0.0, 0.0, -1.0, 2.0, 0.0])
FLOWS = ("noise only", "tare only", "auto-zero", "temperature compensation", "both")


def motion(t: float) -> np.ndarray:
    return PRESS_POSE if any(a <= t < b for a, b in PRESSES) else np.zeros(5)


def drift() -> Drift:
    return Drift.typical(8, seed=0, ramp_degc=5.0, ramp_s=240.0, creep_tau=120.0)


def bus_for(sensor, cmap, tin, clock, d: Drift | None, seed: int, mover=None):
    return SimBus.for_channel_map(cmap, sensor, np.zeros(5), clock=clock, noise=sensor.gmr.noise, seed=seed,
                                  motion=mover, drift=d, thermistor=tin)


def fit_compensation(sensor, cmap, tin, work: Path):
    """The compensation a `capture --temperature 20,25,30` of three poses gives."""
    d = drift().steady(25.0)
    clock = VirtualClock()
    bus = bus_for(sensor, cmap, tin, clock, d, seed=11)
    array = AdcArray(bus, cmap, clock=clock)
    array.probe()
    array.setup()
    thermo = Thermometer(array, tin)
    sched = Schedule(np.array([[0, 0, 0, 0, 0], [1, 0, -1, 0, 0], [-1, 1, -0.5, 0, 0]], dtype=float),
                     ("dx", "dy", "dz"), "bench")
    rows, ids, temps = [], [], []
    for T in (20.0, 25.0, 30.0):
        d.start_degc = T
        path = work / f"cap.T{T:g}.csv"
        capture(array, sched, path, samples=32, set_pose=bus.set_pose, clock=clock, max_spread=0.01)
        from fitgen.physics.dataset import load_dataset

        ds = load_dataset(path)
        clock.sleep(1.0)
        rows.append(ds.inputs), ids.append(np.arange(ds.n_rows)), temps.append(np.full(ds.n_rows, thermo.read()))
    return fit_tempcomp(np.vstack(rows), np.concatenate(ids), np.concatenate(temps), t0=25.0)


class Collect:
    """The readout's observer: keeps time, estimates and auto-zero updates."""

    def __init__(self):
        self.t, self.out = [], []

    def __call__(self, sample: dict) -> None:
        self.t.append(sample["t"])
        self.out.append(list(sample["out"].values()))


def run_flow(flow: str, sensor, model, cmap, tin, tc, reference=None) -> dict:
    clock = VirtualClock()
    d = None if flow == "noise only" else drift()
    bus = bus_for(sensor, cmap, tin, clock, d, seed=5)
    array = AdcArray(bus, cmap, clock=clock)
    array.probe()
    array.setup()
    thermo = Thermometer(array, tin)
    reference = rest_reference("paper", model.n_inputs) if reference is None else reference
    t0 = tare(array, reference, 50)
    noise = t0.noise_floor(array.lsb)
    start = clock.monotonic()
    bus.feed.motion = lambda t: motion(t - start)
    az = None
    if flow in ("auto-zero", "both", "now"):
        az = AutoZero.for_model(model, reference, noise, zero=t0.offsets)
    elif flow == "before":
        az = AutoZero(reference, noise, model.output_names, zero=t0.offsets,
                      settings=AutoZeroSettings(test="sample"))
    comp = tc if flow in ("temperature compensation", "both") else None
    corrections = Corrections(t0.offsets, comp, az)
    col = Collect()
    reader = Readout(array, PythonEngine(model), None, LineFormat("csv", 8, model.output_names), clock=clock,
                     corrections=corrections, thermometer=thermo, observer=col)
    reader.run(rate=RATE, duration=DURATION)
    t = np.array(col.t) - clock.epoch - start
    out = np.array(col.out)
    updates = [] if az is None else [u.t - clock.epoch - start for u in az.updates]
    return {"t": t, "out": out, "updates": updates, "temp_end": thermo.read()}


def analyse(res: dict) -> dict:
    t, out = res["t"], res["out"]
    rest = np.ones(t.size, dtype=bool)
    pressed = np.zeros(t.size, dtype=bool)
    for a, b in PRESSES:
        rest &= ~((t >= a) & (t < b + 2.0))
        pressed |= (t >= a + 1.0) & (t < b)
    e = out[rest]
    inside = [u for u in res["updates"] if any(a <= u < b + 0.5 for a, b in PRESSES)]
    return {"rms": np.sqrt(np.mean(e * e, axis=0)), "max": np.abs(e).max(axis=0),
            "press_dz": float(out[pressed, 2].mean()), "press_dz_err": float(np.abs(out[pressed, 2] + 1.0).max()),
            "updates": len(res["updates"]), "updates_in_press": len(inside)}


def main() -> None:
    ap = parser(__doc__)
    ap.add_argument("--plot", metavar="DIR", help="write drift.png here")
    args = ap.parse_args()
    if args.plot:  # made now: a folder found wrong after minutes of work would lose the run
        try:
            make_folder(args.plot)
        except InputError as e:
            ap.error(str(e))
    sensor = load_sensor("paper").with_transfer("gmr")
    cmap = parse_spec(ADC)
    tin = parse_temperature_input(THERMISTOR)
    log("fitting the model (auto family)")
    train = simulate(sensor, grid_poses(PAPER_GRIDS["paper-sim"]))
    model, family = fit_auto(train, None, FitSettings(), sensor)
    log(f"model: family {family['name']}")
    with tempfile.TemporaryDirectory(prefix="bench-drift-") as tmp:
        tc = fit_compensation(sensor, cmap, tin, Path(tmp))
    truth = drift()
    log(f"compensation fitted: offset error up to {np.abs(tc.offset - truth.offset_tc).max() * 1e3:.3g} mV/degC, "
        f"gain error up to {np.abs(tc.gain - truth.gain_tc).max() * 100:.3g} %/degC")
    results = {}
    for flow in FLOWS:
        results[flow] = run_flow(flow, sensor, model, cmap, tin, tc)
        log(f"{flow}: {len(results[flow]['t'])} samples")
    stats = {f: analyse(r) for f, r in results.items()}
    base = stats["noise only"]["rms"]
    outs = model.output_names
    rows = []
    for f in FLOWS:
        s = stats[f]
        ratio = s["rms"] / base
        rows.append([f] + [f"{fmt(s['rms'][j])} / {fmt(s['max'][j])}" for j in range(len(outs))]
                    + [fmt(ratio.max()), outs[int(np.argmax(ratio))], fmt(s["press_dz"]), fmt(s["press_dz_err"]),
                       str(s["updates"]), str(s["updates_in_press"])])
    print("# Drift at rest (bench/drift.py)\n")
    print(f"Model family {family['name']}; {DURATION:g} s at {RATE:g} Hz on a virtual clock; temperature 25 -> "
          f"{results['both']['temp_end']:.2f} degC (thermistor at the end); presses at "
          + ", ".join(f"{a:g}-{b:g} s" for a, b in PRESSES) + " to dz = -1 mm, thx = 2 deg.\n")
    print(f"Compensation fitted from the simulated capture: offsets within "
          f"{np.abs(tc.offset - truth.offset_tc).max() * 1e3:.3g} mV/degC and gains within "
          f"{np.abs(tc.gain - truth.gain_tc).max() * 100:.3g} %/degC of the simulated drift's.\n")
    head = (["flow"] + [f"{o} RMS / max at rest" for o in outs]
            + ["worst RMS / noise only", "(output)", "dz in presses (mean)", "dz in presses, max error",
               "auto-zero updates", "updates in presses"])
    print(table(head, rows))
    ok = (stats["both"]["rms"] / base).max() <= 3.0
    print(f"\nAcceptance (worst output at rest within 3x the noise-only RMS with auto-zero and compensation; no "
          f"update in a press): **{'PASS' if ok and stats['both']['updates_in_press'] == 0 else 'FAIL'}**")
    unit_runs = rest_test(sensor, model, cmap, tin, results)["unit 7's own equations, unit 7"]
    if args.plot:
        log(f"plot: {plot(results, unit_runs, outs, args.plot)}")
    log("done")


def plot(results: dict, unit_runs: dict, outs, folder) -> Path:
    """drift.png in ``folder``: dz and thx at rest per flow, and the unit's thy before and now."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(10, 8.5), sharex=True)
    for ax, j, unit in ((axes[0], 2, "mm"), (axes[1], 3, "deg")):
        # "both" last and thin over a wider "noise only": drawn after it and as wide, noise only hid it whole
        for f, c, w in (("tare only", "C3", 0.6), ("noise only", "0.6", 1.6), ("both", "C0", 0.4)):
            r = results[f]
            ax.plot(r["t"], r["out"][:, j], lw=w, color=c, label=f)
        for a, b in PRESSES:
            ax.axvspan(a, b, color="0.9", zorder=0)
        ax.set_ylabel(f"{outs[j]} [{unit}]")
        ax.set_ylim(-0.3 if j == 2 else -1.5, 0.3 if j == 2 else 1.5)
    for u in results["both"]["updates"]:
        axes[0].axvline(u, color="C0", lw=0.3, alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    ax = axes[2]  # a unit's own equations: auto-zero testing every sample never ran; the window's mean does
    for f, c, label in (("before", "C3", "auto-zero, every sample tested (before)"),
                        ("now", "C0", "auto-zero, the window's mean tested (now)")):
        r = unit_runs[f]
        ax.plot(r["t"], r["out"][:, 4], lw=0.4, color=c, label=f"{label}: {len(r['updates'])} updates")
    for a, b in PRESSES:
        ax.axvspan(a, b, color="0.9", zorder=0)
    ax.set_ylabel("unit 7: thy [deg]")
    ax.set_ylim(-6, 6)
    ax.legend(loc="upper left", fontsize=8)
    axes[2].set_xlabel("time [s] (presses shaded, clipped; thin lines: auto-zero updates)")
    fig.suptitle("Estimates at rest under a 5 degC ramp and creep\ntop two: tare only against auto-zero + "
                 "compensation; bottom: a unit's own equations, auto-zero alone", fontsize=11)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, metadata={"Software": None})
    return write_in_folder(folder, "drift.png", buf.getvalue())


def rest_test(sensor, model, cmap, tin, results: dict) -> dict:
    """The second table: auto-zero per sample (before) against the window's mean (now), per model; the runs of
    each model by flow."""
    log("fitting the paper's procedure (noise 0) and unit 7's own equations")
    paper = fit_model(simulate(sensor, grid_poses(PAPER_GRIDS["paper-sim"])), settings=FitSettings.exact())
    unit = draw_unit(sensor, 7)[0].with_transfer("gmr")
    poses = np.vstack([grid_poses(PAPER_GRIDS["paper-sim"]),
                       random_poses(5000, DEFAULT_RANGES, np.random.default_rng(0))])
    unit_model = fit_auto(simulate(unit, poses), None, FitSettings(), unit)[0]
    unit_ref = readings(unit, np.zeros(5), adc_bits=0)[0]
    cases = (("default fit, the drawing", sensor, model, None), ("paper's procedure, the drawing", sensor, paper, None),
             ("unit 7's own equations, unit 7", unit, unit_model, unit_ref))
    rows, every = [], {}
    for name, sen, m, ref in cases:
        runs = every[name] = {"noise only": results["noise only"], "tare only": results["tare only"]} \
            if m is model else {}
        for flow in ("noise only", "tare only", "before", "now"):
            if flow not in runs:
                runs[flow] = run_flow(flow, sen, m, cmap, tin, None, ref)
                log(f"{name}, {flow}: {len(runs[flow]['t'])} samples")
        st = {f: analyse(r) for f, r in runs.items()}
        base = st["noise only"]["rms"]
        for flow in ("tare only", "before", "now"):
            s = st[flow]
            ratio = s["rms"] / base
            rows.append([name, flow, fmt(ratio.max()), m.output_names[int(np.argmax(ratio))],
                         " / ".join(fmt(x) for x in base), fmt(s["press_dz"]), str(s["updates"]),
                         str(s["updates_in_press"])])
    print("\n## Auto-zero's rest test: every sample (before) against the window's mean (now)\n")
    print("The same run without compensation. Worst output's RMS at rest over the noise-only run's, and the "
          "noise-only RMS at rest per output (dx, dy, dz mm; thx, thy deg).\n")
    print(table(["model, sensor", "flow", "worst RMS / noise only", "(output)", "noise-only RMS at rest",
                 "dz in presses (mean)", "auto-zero updates", "updates in presses"], rows))
    return every


if __name__ == "__main__":
    main()
