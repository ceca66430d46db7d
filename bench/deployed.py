"""Deployed accuracy: what the estimator a user flashes really does, against what the fit reports.

Before the fit became noise-aware and precision-aware (fitgen.fitting.fit.FitSettings), a model fitted on
noise-free simulated readings reported errors that its generated C, fed the sensor's noisy
readings and computing in float, did not reach. This benchmark measures both sides for the flows
below, on the four layouts of docs/layouts.md and both transfers; docs/deployed-accuracy.md
holds its output.

Run:

    python bench/deployed.py > out.md            # tables on stdout, progress on stderr; ~3 min on 2 cores
    python bench/deployed.py --quick > quick.md  # paper and ring-vertical, raw; 500 poses, 2 draws

Needs gcc and valgrind (instruction counts) and arm-none-eabi-gcc/size/nm with newlib (flash);
`bash scripts/test --co -q` installs them.

Data (deterministic):

- Training, every flow but `replicas`: the paper-sim grid (1,875 poses) simulated without noise,
  as `fitgen simulate --grid paper-sim`. `replicas`: 4 copies of the grid with the sensor's
  noise (one simulate call, noise seed 2), fitted with FitSettings.exact().
- Held out: 2,000 random poses uniform in fitgen.physics.simulate.DEFAULT_RANGES (pose seed 2026),
  never used in fitting; noise-free, and with the sensor's noise (5 draws, noise seeds 1..5).

Flows (models), per configuration (layout x transfer):

1. `before`: FitSettings.exact() (the paper's procedure: data as given, exact arithmetic).
   `before, no-roots`: the same with the no-roots family, for a fixed-point figure (and float,
   to tell the family's part from the arithmetic's).
2. `noise-aware`: FitSettings(precision=None) (the sensor's noise added in expectation).
3. `default`: FitSettings() (noise and float rounding in expectation).
4. `replicas`: the noisy-replica baseline above (double is its reference).
5. `fixed target`: FitSettings(precision="fixed", exponents=FAMILIES["no-roots"]).
6. `harmonics`: FitSettings.family("harmonics") (the default's noise and float rounding, with the
   ring's harmonic monomials among the candidates; no fixed point).

Measured, per flow x precision x output:

- model error: Model.predict (double Python) on the noise-free held-out readings, max and RMS.
- C deviation: the largest |generated C - Model.predict| on the noise-free held-out readings
  (gcc -O2, fitgen.c.compiled.CompiledModel; style unrolled; float: inputs rounded to float32 first;
  fixed: inputs turned into the ADC codes of fitgen.equations.inputscale.sensor_input_scale). Rounding's share:
  that deviation over the model's held-out max error.
- deployed error: the C on the noisy held-out readings (all draws pooled) against the true
  poses, RMS and max; its RMS over the `replicas` flow's double-C noisy RMS.
- floor: the Cramer-Rao bound (fitgen.physics.observe.cramer_rao, the sensor's noise, all five components
  estimated) at each of the held-out poses; the table gives its RMS over the poses (the
  floor of an unbiased estimator's RMS error there) and, in brackets, its median. A pose the
  layout cannot resolve has an infinite bound and makes the RMS inf; the table then also gives
  how many poses are inf and the RMS over the others.

Per flow: terms per output; instructions per estimate inside tm_estimate of the float unrolled C
(callgrind, x86-64, fitgen.c.cost); flash it adds on a Cortex-M4F (float unrolled) and, for the
fixed-point flows, on a Cortex-M0 (fitgen.c.cost.arm_sizes, linked newlib program over an empty main).
"""

from __future__ import annotations

import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from fitgen.base.errors import InputError
from fitgen.fitting.fit import FitSettings, fit_model
from fitgen.physics.pose import POSE_NAMES
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import DEFAULT_RANGES, PAPER_GRIDS, grid_poses, pose_rng, random_poses, simulate
from fitgen.equations.terms import FAMILIES
from fitgen.equations.inputscale import sensor_input_scale as fixed_scale
from fitgen.c import cost
from fitgen.c.compiled import CompiledModel
from benchutil import START, cramer_rao_floor, fmt, log, parser, stats, table

LAYOUTS = ("paper", "two-radii", "ring-vertical", "two-rings")
TRANSFERS = ("raw", "gmr")
QUICK_CONFIGS = (("paper", "raw"), ("ring-vertical", "raw"))
N_HELD, N_HELD_QUICK = 2000, 500
NOISE_DRAWS, NOISE_DRAWS_QUICK = 5, 2
POSE_SEED = 2026
REPLICA_SEED = 2
REPLICAS = 4
STYLE = "unrolled"
SHARE_LIMIT = 0.05  # acceptance: float rounding's share of the model's held-out max error
RATIO_LIMIT = 1.15  # acceptance: float noisy RMS over the replicas' double noisy RMS
# (flow, FitSettings or "replicas", precisions measured)
FLOWS = (
    ("before", FitSettings.exact(), ("double", "float")),
    ("before, no-roots", FitSettings.exact(exponents=FAMILIES["no-roots"]), ("fixed", "float")),
    ("noise-aware", FitSettings(precision=None), ("double", "float")),
    ("default", FitSettings(), ("double", "float")),
    ("replicas", "replicas", ("double", "float")),
    ("fixed target", FitSettings(precision="fixed", exponents=FAMILIES["no-roots"]), ("fixed", "float")),
    ("harmonics", FitSettings.family("harmonics"), ("double", "float")),
)
FIXED_FLOWS = tuple(name for name, _, precs in FLOWS if "fixed" in precs)


def pct(x: float | None) -> str:
    if x is None:
        return "-"
    if not np.isfinite(x):
        return "inf"
    return f"{100 * x:.2g} %" if x < 0.1 else f"{100 * x:.0f} %"


class Config:
    """One layout x transfer: its data, its fits, its measurements."""

    def __init__(self, layout: str, transfer: str, n_held: int, draws: int):
        self.layout, self.transfer = layout, transfer
        self.name = f"{layout} {transfer}"
        self.sensor = load_sensor(layout).with_transfer(transfer)
        self.grid = grid_poses(PAPER_GRIDS["paper-sim"])
        self.poses = random_poses(n_held, DEFAULT_RANGES, pose_rng(POSE_SEED))
        self.clean = simulate(self.sensor, self.poses).inputs
        self.noisy = np.vstack([simulate(self.sensor, self.poses, noise=self.sensor.noise, seed=s).inputs
                                for s in range(1, draws + 1)])
        self.truth_noisy = np.tile(self.poses, (draws, 1))
        self.scale = fixed_scale(self.sensor)
        self.models: dict = {}
        self.model_err: dict = {}  # flow -> (max, rms) per output
        self.deployed: dict = {}  # (flow, precision) -> dict
        self.cost: dict = {}  # flow -> dict
        self.notes: list[str] = []

    def floor(self) -> None:
        f = cramer_rao_floor(self.sensor, self.poses)
        self.floor_rms, self.floor_median, self.floor_inf, self.floor_finite_rms = (
            f["rms"], f["median"], f["inf"], f["finite_rms"])

    def fit(self) -> None:
        train = simulate(self.sensor, self.grid)
        for flow, settings, _ in FLOWS:
            if settings == "replicas":
                data = simulate(self.sensor, np.tile(self.grid, (REPLICAS, 1)), noise=self.sensor.noise,
                                seed=REPLICA_SEED)
                model = fit_model(data, settings=FitSettings.exact(), sensor=self.sensor)
            else:
                model = fit_model(train, settings=settings, sensor=self.sensor)
            self.models[flow] = model
            mx, rms = stats(model.predict(self.clean) - self.poses)
            self.model_err[flow] = (mx, rms)
        added = self.models["default"].fit_info.get("noise", {}).get("added")
        self.noise_added = added

    def measure(self, flow: str, precision: str, work: Path) -> dict:
        model = self.models[flow]
        ref = model.predict(self.clean)
        n = len(self.clean)
        both = np.vstack([self.clean, self.noisy])
        kw = {}
        if precision == "fixed":
            kw = {"input_lsb": self.scale[0], "input_offset": self.scale[1]}
        with CompiledModel(model, precision, STYLE, workdir=work, **kw) as cm:
            if precision == "fixed":
                x = cm.fixed.codes_of(both)
            elif precision == "float":
                x = both.astype(np.float32).astype(float)
            else:
                x = both
            out, status = cm.predict(x)
        dev = np.abs(out[:n] - ref).max(axis=0)
        noisy_max, noisy_rms = stats(out[n:] - self.truth_noisy)
        return {"dev": dev, "share": dev / self.model_err[flow][0], "noisy_max": noisy_max,
                "noisy_rms": noisy_rms, "nonfinite_status": int(np.sum(status < 0))}

    def measure_cost(self, flow: str, work: Path) -> dict:
        model = self.models[flow]
        res = {"terms": [len(e.terms) for e in model.equations]}
        inputs = cost.write_inputs(self.clean, work / "inputs.f64")
        binary = cost.build_bench(model, STYLE, "float", False, work / "bench")
        res["instructions"] = cost.instruction_counts(binary, inputs, work / "bench", mix=False, repeat=False)["fn"]
        res["m4f_flash"] = cost.arm_sizes(model, STYLE, "float", False, work / "m4f")["linked"]
        if flow in FIXED_FLOWS:
            res["m0_flash"] = cost.arm_sizes(model, "table", "fixed", False, work / "m0",
                                             cc=cost.ARM_CORES["cortex-m0"], input_lsb=self.scale[0],
                                             input_offset=self.scale[1])["linked"]
        return res

    def run(self, jobs: int) -> None:
        log(f"{self.name}: floor (Cramer-Rao bounds at {len(self.poses)} held-out poses)")
        self.floor()
        log(f"{self.name}: fitting {len(FLOWS)} flows")
        self.fit()
        units = [("dep", flow, p) for flow, _, precs in FLOWS for p in precs]
        units += [("cost", flow, None) for flow, _, _ in FLOWS]
        log(f"{self.name}: building and measuring {len(units)} C builds")
        with tempfile.TemporaryDirectory(prefix="fitgen-deployed-") as tmp:
            def one(item):
                i, (kind, flow, prec) = item
                work = Path(tmp) / f"u{i}"
                work.mkdir()
                try:
                    if kind == "dep":
                        return item, self.measure(flow, prec, work), ""
                    return item, self.measure_cost(flow, work), ""
                except (InputError, RuntimeError) as exc:
                    return item, None, str(exc).splitlines()[0][:200]

            with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
                for (_, (kind, flow, prec)), res, err in pool.map(one, enumerate(units)):
                    if res is None:
                        self.notes.append(f"{flow} {prec or 'cost'}: not measured: {err}")
                    elif kind == "dep":
                        self.deployed[(flow, prec)] = res
                    else:
                        self.cost[flow] = res
        ref = self.deployed.get(("replicas", "double"))
        for (flow, prec), d in self.deployed.items():
            d["ratio"] = None if ref is None else d["noisy_rms"] / ref["noisy_rms"]
            if d["nonfinite_status"]:
                self.notes.append(f"{flow} {prec}: {d['nonfinite_status']} rows with a non-finite status")
        log(f"{self.name}: done")

    # --- summaries ------------------------------------------------------------------------

    def worst(self, flow: str, prec: str, key: str) -> float | None:
        d = self.deployed.get((flow, prec))
        return None if d is None or d[key] is None else float(np.max(d[key]))

    def cost_ratio(self, key: str, a: str = "default", b: str = "before") -> float | None:
        if a in self.cost and b in self.cost and key in self.cost[a] and key in self.cost[b]:
            return self.cost[a][key] / self.cost[b][key]
        return None


def report(configs: list[Config], n_held: int, draws: int) -> None:
    outs = POSE_NAMES
    print("# Deployed accuracy (bench/deployed.py)\n")
    print(f"Held out: {n_held} random poses in the paper-sim box (pose seed {POSE_SEED}); noisy: "
          f"{draws} draws of the sensor's noise (seeds 1..{draws}). C: gcc -O2, style {STYLE}; float inputs "
          "rounded to float32; fixed inputs as ADC codes. Errors in mm (dx, dy, dz) and deg (thx, thy).\n")

    print("## Summary\n")
    print("Worst over the five outputs. Share: the float C's largest deviation from the double model on "
          "noise-free held-out readings over the model's held-out max error. Ratio: the float C's RMS error on "
          "noisy readings over the `replicas` flow's double-C RMS error on the same readings. Cost ratios: "
          "`default` over `before`, float unrolled C (instructions per estimate on x86-64, Cortex-M4F flash). "
          "Fixed: the fixed-point C's share for `before, no-roots` and `fixed target`, and their Cortex-M0 "
          "flash ratio.\n")
    rows = []
    for c in configs:
        rows.append([c.name, pct(c.worst("before", "float", "share")), pct(c.worst("default", "float", "share")),
                     fmt(c.worst("before", "float", "ratio")), fmt(c.worst("default", "float", "ratio")),
                     fmt(c.cost_ratio("instructions")), fmt(c.cost_ratio("m4f_flash")),
                     pct(c.worst("before, no-roots", "fixed", "share")),
                     pct(c.worst("fixed target", "fixed", "share")),
                     fmt(c.cost_ratio("m0_flash", "fixed target", "before, no-roots"))])
    print(table(["configuration", "float share, before", "float share, default", "float RMS / replicas, before",
                 "float RMS / replicas, default", "instructions default / before", "M4F flash default / before",
                 "fixed share, before no-roots", "fixed share, fixed target", "M0 flash fixed target / before no-roots"],
                rows))
    print()

    for c in configs:
        print(f"## {c.name}\n")
        print(f"Sensor `{c.layout}`, transfer `{c.transfer}`, noise {c.sensor.noise:g} {c.sensor.units} rms; "
              f"the noise-aware fits added {fmt(c.noise_added)} {c.sensor.units}. Fixed point: {c.scale[2]}.\n")
        for note in c.notes:
            print(f"- {note}")
        if c.notes:
            print()

        print("### Model and cost per flow\n")
        print("Model error: Model.predict (double) on the noise-free held-out readings, max / RMS. Terms per "
              "output dx/dy/dz/thx/thy. Instructions and M4F flash: float unrolled C; M0 flash: fixed-point C.\n")
        rows = []
        for flow, _, _ in FLOWS:
            mx, rms = c.model_err[flow]
            k = c.cost.get(flow, {})
            terms = k.get("terms") or [len(e.terms) for e in c.models[flow].equations]
            rows.append([flow] + [f"{fmt(mx[j])} / {fmt(rms[j])}" for j in range(len(outs))]
                        + ["/".join(map(str, terms)) + f" ({sum(terms)})",
                           "-" if k.get("instructions") is None else f"{k['instructions']:.0f}",
                           str(k.get("m4f_flash", "-")), str(k.get("m0_flash", "-"))])
        print(table(["flow"] + list(outs) + ["terms", "instructions", "M4F flash [B]", "M0 flash [B]"], rows))

        print("\n### Rounding: the C against the double model, noise-free held-out readings\n")
        print("Largest |C - Model.predict| (share of the model's held-out max error).\n")
        rows = []
        for flow, _, precs in FLOWS:
            for p in precs:
                d = c.deployed.get((flow, p))
                rows.append([flow, p] + (["-"] * len(outs) if d is None else
                                         [f"{fmt(d['dev'][j])} ({pct(d['share'][j])})" for j in range(len(outs))]))
        print(table(["flow", "precision"] + list(outs), rows))

        print("\n### Deployed: the C on noisy held-out readings\n")
        print("RMS / max error against the true poses (RMS over the `replicas` flow's double C RMS). Floor: "
              "the Cramer-Rao bound at the held-out poses, RMS over the poses (median); where some poses "
              "cannot be resolved (infinite bound) the RMS is inf and the RMS over the resolvable poses "
              "alone follows.\n")
        rows = []
        for flow, _, precs in FLOWS:
            for p in precs:
                d = c.deployed.get((flow, p))
                rows.append([flow, p] + (["-"] * len(outs) if d is None else
                                         [f"{fmt(d['noisy_rms'][j])} / {fmt(d['noisy_max'][j])} "
                                          f"({fmt(d['ratio'][j]) if d['ratio'] is not None else '-'}x)"
                                          for j in range(len(outs))]))
        floor = []
        for j in range(len(outs)):
            cell = f"{fmt(c.floor_rms[j])} ({fmt(c.floor_median[j])})"
            if c.floor_inf[j]:
                cell += f"; {int(c.floor_inf[j])} poses inf, RMS over the rest {fmt(c.floor_finite_rms[j])}"
            floor.append(cell)
        rows.append(["floor (Cramer-Rao)", "-"] + floor)
        print(table(["flow", "precision"] + list(outs), rows))
        print()

    print("## Acceptance\n")
    print(f"For the `default` flow, on every configuration and output: the float C's rounding share <= "
          f"{100 * SHARE_LIMIT:g} % and its noisy RMS <= {RATIO_LIMIT:g}x the `replicas` flow's (double C).\n")
    misses = []
    checked = 0
    for c in configs:
        d = c.deployed.get(("default", "float"))
        if d is None or d["ratio"] is None:
            misses.append(f"{c.name}: not measured")
            continue
        for j, o in enumerate(outs):
            checked += 1
            if not d["share"][j] <= SHARE_LIMIT:
                misses.append(f"{c.name} {o}: share {pct(d['share'][j])}")
            if not d["ratio"][j] <= RATIO_LIMIT:
                misses.append(f"{c.name} {o}: noisy RMS {fmt(d['ratio'][j])}x replicas")
    worst_share = max((c.worst("default", "float", "share") or 0.0) for c in configs)
    worst_ratio = max((c.worst("default", "float", "ratio") or 0.0) for c in configs)
    verdict = "PASS" if not misses else "FAIL"
    print(f"**{verdict}**: {checked} configuration x output pairs checked; worst share {pct(worst_share)}, "
          f"worst ratio {fmt(worst_ratio)}x.\n")
    for m in misses:
        print(f"- miss: {m}")


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--quick", action="store_true",
                    help="paper and ring-vertical, raw; 500 held-out poses, 2 noise draws")
    ap.add_argument("--jobs", type=int, default=2, help="parallel C builds and measurements (default 2)")
    args = ap.parse_args(argv)
    if args.quick:
        pairs, n_held, draws = QUICK_CONFIGS, N_HELD_QUICK, NOISE_DRAWS_QUICK
    else:
        pairs = tuple((lay, t) for lay in LAYOUTS for t in TRANSFERS)
        n_held, draws = N_HELD, NOISE_DRAWS
    configs = []
    for lay, t in pairs:
        c = Config(lay, t, n_held, draws)
        c.run(args.jobs)
        configs.append(c)
    report(configs, n_held, draws)
    log(f"done: {len(configs)} configurations in {time.monotonic() - START:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
