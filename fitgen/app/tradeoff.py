"""Accuracy against cost over the knobs a user can turn: penalty per term, cap on terms, candidate
family, precision, code style and refinement steps (fitgen.equations.refine: swept on the harmonics family,
in float and double, for scenes that estimate the whole pose).

One fit per (k, cap, family, refinement) on the scene's grid, simulated noise-free with the sensor; every
precision and style of that fit is then measured on held-out random poses in the scene's box
(noise-free, and with the sensor's noise in several draws) and in cost: terms, floating-point
operations by kind as the templates write them, x86-64 instructions per estimate counted by
callgrind (deterministic), and the flash the estimator adds to a Cortex-M program.

The score of a point is the worst output's RMS error with noise over its target (<= 1 meets the
target); the Pareto front is taken on (instructions, score) and the recommended point is the
cheapest in instructions that meets the target (ties: less flash).
"""

from __future__ import annotations

import csv
import io
import itertools
import math
import shutil
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fitgen.base.errors import InputError
from fitgen.equations.fixedpoint import sensor_input_scale as fixed_scale
from fitgen.fitting.fit import FitSettings, fit_model
from fitgen.equations.model import Model
from fitgen.physics.pose import POSE_NAMES, POSE_UNITS
from fitgen.physics.scenes import Scene, unresolved_warnings
from fitgen.physics.simulate import pose_rng, random_poses, simulate

K_VALUES = ("aic", "bic", 6.0)
CAPS = (None, 20, 8)
FAMILY_NAMES = ("all", "no-roots", "integer", "harmonics")
NO_FIXED = ("harmonics",)  # families fixed point cannot generate (their terms divide)
PRECISIONS = ("double", "float", "fixed")
STYLES = ("table", "unrolled")
REFINE_STEPS = (0, 1)
REFINED_FAMILIES = ("harmonics",)  # the refinement is swept on these (docs/refine.md measures it on them)
FIXED_STYLE = "-"  # the fixed-point header is straight-line code: the style knob does not apply
OP_KINDS = ("mul", "add", "div", "sqrt", "cbrt")
# Cortex-M core whose flash is reported, per precision (see fitgen.c.cost.ARM_CORES)
CORE_OF = {"double": "cortex-m4f", "float": "cortex-m4f", "fixed": "cortex-m0"}
ACCURACY_TIE = 0.01  # when no point meets the target: scores within 1 % of the best count as equal
N_HELD = 1000
NOISE_DRAWS = 5


@dataclass(frozen=True)
class Knobs:
    """One point of the sweep. ``k``: "aic", "bic" or a number (penalty per term)."""

    k: str | float
    max_terms: int | None
    family: str
    precision: str
    style: str
    refine: int = 0  # Gauss-Newton steps after the equations (fitgen.equations.refine)

    @property
    def fit_key(self) -> tuple:
        return (self.k, self.max_terms, self.family, self.refine)

    @property
    def method(self) -> str:
        """The family, and the refinement if any: ``harmonics+refine1``."""
        return self.family + (f"+refine{self.refine}" if self.refine else "")

    @property
    def label(self) -> str:
        k = self.k if isinstance(self.k, str) else f"k={self.k:g}"
        return f"{k} cap={self.max_terms or '-'} {self.method} {self.precision} {self.style}"

    def settings(self) -> FitSettings:
        k = 2.0 if self.k == "aic" else self.k
        return FitSettings.family(self.family, k=k, max_terms=self.max_terms, refine=self.refine)


def _styles(precision: str) -> tuple[str, ...]:
    return (FIXED_STYLE,) if precision == "fixed" else STYLES


def _possible(points: list[Knobs]) -> list[Knobs]:
    return [k for k in points if not (k.precision == "fixed" and (k.family in NO_FIXED or k.refine))
            and not (k.refine and k.family not in REFINED_FAMILIES)]


def full_grid() -> list[Knobs]:
    """Every combination: 3 penalties x 3 caps x (3 families x (double, float in 2 styles; fixed) and
    harmonics x (double, float in 2 styles) x (no refinement, one step)) = 207 points."""
    return grid_from()


def quick_grid() -> list[Knobs]:
    """A subset that runs in a few minutes: AIC and BIC x every cap x every family, each in every
    precision in the unrolled style (the cheaper one); plus the table style and the penalty 6 for
    the default fit (AIC, no cap, all kinds)."""
    pts = [Knobs(k, cap, fam, p, _styles(p)[-1])
           for k, cap, fam, p in itertools.product(("aic", "bic"), CAPS, FAMILY_NAMES, PRECISIONS)]
    pts += [Knobs("aic", None, "all", p, "table") for p in PRECISIONS if p != "fixed"]
    pts += [Knobs(6.0, None, fam, p, _styles(p)[-1]) for fam in ("all", "integer") for p in PRECISIONS]
    pts += [Knobs("aic", None, "harmonics", "float", "unrolled", 1)]
    return _possible(pts)


def grid_from(k=None, max_terms=None, family=None, precision=None, style=None, refine=None) -> list[Knobs]:
    """The product of the given value lists, each knob not given taking all its values (the
    refinement only where it is swept: REFINED_FAMILIES, float and double)."""
    ks, caps = k or K_VALUES, max_terms or CAPS
    fams, precs, styles = family or FAMILY_NAMES, precision or PRECISIONS, style or STYLES
    return _possible([Knobs(kk, cap, fam, p, s, r)
                      for kk, cap, fam, p, r in itertools.product(ks, caps, fams, precs, refine or REFINE_STEPS)
                      for s in (_styles(p) if p == "fixed" else styles)])


def parse_knob_list(name: str, spec: str) -> list:
    """A comma-separated list of one knob's values (``--k aic,6``, ``--max-terms none,8`` ...)."""
    out = []
    for part in (x.strip() for x in spec.split(",")):
        if name == "k":
            if part in ("aic", "bic"):
                val = part
            else:
                try:
                    val = float(part)
                except ValueError:
                    val = math.nan
                if not (val > 0 and math.isfinite(val)):
                    raise InputError(f"--k takes aic, bic or numbers > 0, got {part!r}")
        elif name == "refine":
            if not (part.isdigit() and int(part) <= 8):
                raise InputError(f"--refine takes step counts from 0 to 8, got {part!r}")
            val = int(part)
        elif name == "max_terms":
            if part == "none":
                val = None
            elif part.isdigit() and int(part) >= 1:
                val = int(part)
            else:
                raise InputError(f"--max-terms takes 'none' or whole numbers >= 1, got {part!r}")
        else:
            allowed = {"family": FAMILY_NAMES, "precision": PRECISIONS, "style": STYLES}[name]
            if part not in allowed:
                raise InputError(f"--{name} takes values from {', '.join(allowed)}, got {part!r}")
            val = part
        if val not in out:
            out.append(val)
    return out


def parse_target(spec: str | None, outputs: tuple[str, ...]) -> dict[str, float]:
    """``dz=0.1 thx=2`` for the scene's outputs; the rest from fitgen.physics.observe.DEFAULT_ACCURACY."""
    from fitgen.base.parse import parse_assignments
    from fitgen.physics.observe import DEFAULT_ACCURACY

    target = {o: DEFAULT_ACCURACY[o] for o in outputs}
    if spec is not None:
        given = parse_assignments(spec, POSE_NAMES, "--target")
        if not given:
            raise InputError(f"--target {spec!r}: expected NAME=NUMBER, e.g. 'dz=0.1 thx=2'")
        for name, value in given.items():
            if name not in outputs:
                raise InputError(f"--target names {name}, which the scene does not estimate "
                                 f"(its outputs: {', '.join(outputs)})")
            if not (value > 0 and math.isfinite(value)):
                raise InputError(f"--target {name} must be a finite number > 0, got {value:g}")
            target[name] = value
    return target


# --- the front and the recommendation ---------------------------------------------------------------

def pareto_front(cost: list[float], score: list[float]) -> list[int]:
    """Indices of the points no other point dominates (lower or equal in both, lower in one),
    in order of cost. Points equal in both are all on the front; a NaN or None is never on it."""
    ok = [i for i in range(len(cost)) if cost[i] is not None and score[i] is not None
          and math.isfinite(cost[i]) and math.isfinite(score[i])]
    front = []
    for i in ok:
        dominated = any(cost[j] <= cost[i] and score[j] <= score[i] and (cost[j] < cost[i] or score[j] < score[i])
                        for j in ok)
        if not dominated:
            front.append(i)
    return sorted(front, key=lambda i: (cost[i], score[i], i))


def recommend(cost: list[float], score: list[float], flash: list[float | None],
              close: float = ACCURACY_TIE) -> tuple[int | None, bool]:
    """(index, met): the fewest instructions among points with score <= 1 (ties: less flash, then
    the lower score); if none meets the target, met False and the most accurate point, where scores
    within a factor ``1 + close`` of the best count as equal (then: fewer instructions, less flash).
    (None, False) when no point was measured."""
    def val(x):
        return math.inf if x is None or not math.isfinite(x) else x

    ok = [i for i in range(len(cost)) if math.isfinite(val(cost[i])) and math.isfinite(val(score[i]))]
    if not ok:
        return None, False
    meet = [i for i in ok if score[i] <= 1.0]
    if meet:
        return min(meet, key=lambda i: (cost[i], val(flash[i]), score[i], i)), True
    best = min(score[i] for i in ok)
    near = [i for i in ok if score[i] <= best * (1 + close)]
    return min(near, key=lambda i: (cost[i], val(flash[i]), score[i], i)), False


# --- measurements ----------------------------------------------------------------------------------

@dataclass
class Point:
    """A measured point: its knobs, cost and accuracy (errors[output] = max, rms, noisy_max, noisy_rms)."""

    knobs: Knobs
    terms: int = 0
    terms_per_output: dict = field(default_factory=dict)
    ops: dict = field(default_factory=dict)
    instructions: float | None = None  # x86-64, inside tm_estimate, per estimate
    loop_instructions: float | None = None  # whole bench loop per estimate
    flash: int | None = None  # bytes the estimator adds to a linked Cortex-M program
    object_flash: int | None = None  # text + data of the estimator's object file
    errors: dict = field(default_factory=dict)
    score: float | None = None
    share: float | None = None  # rounding's share: worst output's deviation from double / the model's max error
    model_hash: str = ""
    note: str = ""


@dataclass
class TradeoffResult:
    sensor: str
    transfer: str
    scene: Scene
    target: dict
    points: list[Point]
    front: list[int]
    recommended: int | None
    met: bool
    warnings: list[str]
    notes: list[str]
    setup: dict
    max_share: float = 0.05
    over_share: list[int] = field(default_factory=list)  # points whose rounding adds more than max_share


def _fixed_backend():
    """fitgen.equations.fixedpoint when it is there (fixed-point generation), else None."""
    try:
        from fitgen.equations import fixedpoint
    except ImportError:
        return None
    return fixedpoint


def _errors(pred: np.ndarray, truth: np.ndarray, noisy_pred: np.ndarray, noisy_truth: np.ndarray,
            outputs: tuple[str, ...], double: np.ndarray, reference: np.ndarray) -> dict:
    """Per output: errors noise-free and with noise, and rounding's share: the largest deviation from
    ``reference`` (the double model on the inputs this precision took) over the ``double`` model's
    own max error."""
    out = {}
    for j, o in enumerate(outputs):
        e, en = np.abs(pred[:, j] - truth[:, j]), np.abs(noisy_pred[:, j] - noisy_truth[:, j])
        model_max = float(np.abs(double[:, j] - truth[:, j]).max())
        dev = float(np.abs(pred[:, j] - reference[:, j]).max())
        out[o] = {"max": float(e.max()), "rms": float(np.sqrt(np.mean(e * e))),
                  "noisy_max": float(en.max()), "noisy_rms": float(np.sqrt(np.mean(en * en))),
                  "deviation": dev, "share": dev / model_max if model_max > 0 else 0.0}
    return out


class _Measure:
    """Measures (model, precision, style) units; shared state: held-out data and tool set-up."""

    def __init__(self, held_inputs, held_truth, noisy_inputs, noisy_truth, outputs, work: Path, have_arm: bool,
                 scale: tuple[float, float] | None = None):
        self.X, self.Y, self.Xn, self.Yn = held_inputs, held_truth, noisy_inputs, noisy_truth
        self.outputs, self.work, self.have_arm, self.scale = outputs, work, have_arm, scale

    def __call__(self, model: Model, precision: str, style: str, tag: str) -> dict:
        from fitgen.c import cost

        folder = self.work / tag
        folder.mkdir()
        both = np.vstack([self.X, self.Xn])
        header, bench_inputs, ref_inputs = {}, self.X, None
        if precision == "double":
            res = {"ops": dict(cost.template_ops(model, style))}
            pred = model.predict(both)  # rounds as the generated double C does, term by term
        elif precision == "float":
            from fitgen.c.compiled import CompiledModel

            res = {"ops": dict(cost.template_ops(model, style))}
            with CompiledModel(model, "float", style, workdir=folder / "vectors") as cm:
                pred = cm.predict(both)[0]
        else:
            from fitgen.equations.fixedpoint import build_fixed

            lsb, offset = self.scale
            fm = build_fixed(model, lsb, offset)
            res = {"ops": fixed_ops(fm)}
            # the numpy model of the integer arithmetic: the C's integers exactly, on the inputs' codes
            pred = fm.to_real(fm.predict_codes(fm.codes_of(both))[0])
            header, bench_inputs = {"input_lsb": lsb, "input_offset": offset}, fm.codes_of(self.X).astype(float)
            # rounding's share is the arithmetic's: double on the values of the codes the C takes
            ref_inputs = fm.code_values(fm.codes_of(self.X))
            style = "table"  # not read by the fixed-point template
        double = model.predict(self.X)
        res["errors"] = _errors(pred[: len(self.X)], self.Y, pred[len(self.X):], self.Yn, self.outputs,
                                double, double if ref_inputs is None else model.predict(ref_inputs))
        inputs_file = cost.write_inputs(bench_inputs, folder / "inputs.f64")
        binary = cost.build_bench(model, style, precision, False, folder / "bench", **header)
        ir = cost.instruction_counts(binary, inputs_file, folder / "bench", mix=False, repeat=False)
        res["instructions"], res["loop_instructions"] = ir["fn"], ir["loop"]
        if self.have_arm:
            a = cost.arm_sizes(model, style, precision, False, folder / "arm", cost.ARM_CORES[CORE_OF[precision]],
                               **header)
            res["flash"], res["object_flash"] = a["linked"], a["text"] + a["data"]
        return res


def fixed_ops(fm) -> dict:
    """Integer operations of a fixed-point plan, by the float kinds: a product (and its shift) is a
    mul, a reciprocal a div, a term a mul and an add."""
    kinds = [op.kind for op in fm.ops]
    return {"mul": kinds.count("mul") + kinds.count("term"), "add": kinds.count("term"), "div": kinds.count("recip"),
            "sqrt": 0, "cbrt": 0}


def sweep(sensor, scene: Scene, grid: list[Knobs], *, target: dict | None = None, seed: int = 0,
          n_held: int = N_HELD, noise_draws: int = NOISE_DRAWS, jobs: int = 2, progress=None,
          max_share: float = 0.05) -> TradeoffResult:
    """Fit, build and measure every point of ``grid`` for ``sensor`` on ``scene``.

    A point whose rounding adds more than ``max_share`` of its model's held-out max error is
    listed in ``over_share`` and is neither on the front nor recommended.

    ``progress(note)`` is called once per measured point. Needs gcc and valgrind; the flash
    figures need arm-none-eabi-gcc/size/nm (left empty, with a note, without them).
    """
    if shutil.which("valgrind") is None:
        raise InputError("valgrind not found: the instruction counts need it (apt-get install valgrind)")
    outputs = scene.outputs
    target = parse_target(None, outputs) if target is None else dict(target)
    notes: list[str] = []
    warnings = unresolved_warnings(sensor, scene, accuracy=target)
    if tuple(outputs) != POSE_NAMES and any(k.refine for k in grid):
        notes.append(f"no refinement: it estimates the whole pose, and scene {scene.name} asks for "
                     f"{','.join(outputs)} only")
        grid = [k for k in grid if not k.refine]
        if not grid:
            raise InputError(f"nothing to sweep: the refinement estimates the whole pose, and scene {scene.name} "
                             f"asks for {','.join(outputs)} only")

    scale = None
    if any(k.precision == "fixed" for k in grid):
        if _fixed_backend() is None:
            notes.append("fixed point skipped: fitgen.equations.fixedpoint is not available in this build")
            grid = [k for k in grid if k.precision != "fixed"]
        else:
            lsb, offset, text = fixed_scale(sensor)
            scale = (lsb, offset)
            notes.append(f"fixed point: int32 input codes, {text}; the held-out inputs are rounded to codes; "
                         "it takes no roots, so points whose fit uses them are not measured")
    have_arm = all(shutil.which(t) for t in ("arm-none-eabi-gcc", "arm-none-eabi-size", "arm-none-eabi-nm"))
    if not have_arm:
        notes.append("flash sizes skipped: arm-none-eabi-gcc/size/nm not found")

    # training: the scene's grid, noise-free; held-out: random poses in its box, seeded
    train = simulate(sensor, scene.poses(), provenance={"scene": scene.name})
    poses = random_poses(n_held, scene.ranges, pose_rng(seed))
    cols = [POSE_NAMES.index(o) for o in outputs]
    clean = simulate(sensor, poses, seed=seed)
    noisy = [simulate(sensor, poses, noise=sensor.noise, seed=seed + 1 + i) for i in range(noise_draws)]
    X, Y = clean.inputs, poses[:, cols]
    Xn, Yn = np.vstack([d.inputs for d in noisy]), np.tile(Y, (noise_draws, 1))

    fits: dict[tuple, Model] = {}
    for kn in grid:
        if kn.fit_key not in fits:
            fits[kn.fit_key] = fit_model(train, outputs, kn.settings(), sensor=sensor)

    points = [Point(kn) for kn in grid]
    units: dict[tuple, list[int]] = {}
    for i, p in enumerate(points):
        m = fits[p.knobs.fit_key]
        p.model_hash = m.sha256
        p.terms_per_output = {e.name: len(e.terms) for e in m.equations}
        p.terms = sum(p.terms_per_output.values())
        units.setdefault((m.sha256, p.knobs.precision, p.knobs.style), []).append(i)

    with tempfile.TemporaryDirectory(prefix="fitgen-tradeoff-") as tmp:
        measure = _Measure(X, Y, Xn, Yn, outputs, Path(tmp), have_arm, scale)

        def one(item):
            n, ((_, precision, style), idx) = item
            model = fits[points[idx[0]].knobs.fit_key]
            try:
                return idx, measure(model, precision, style, f"u{n}"), ""
            except (InputError, RuntimeError) as exc:
                return idx, None, str(exc).splitlines()[0][:200]

        with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
            for idx, res, err in pool.map(one, enumerate(units.items())):
                for i in idx:
                    p = points[i]
                    if res is None:
                        p.note = f"not measured: {err}"
                    else:
                        for key, val in res.items():
                            setattr(p, key, val)
                        p.score = max(p.errors[o]["noisy_rms"] / target[o] for o in outputs)
                        p.share = max(p.errors[o]["share"] for o in outputs)
                if progress:
                    progress(points[idx[0]].knobs.label)

    over = [i for i, p in enumerate(points) if p.share is not None and p.share > max_share]
    for i in over:
        worst = max(outputs, key=lambda o: points[i].errors[o]["share"])
        points[i].note = (f"rounding adds {points[i].share:.1%} of {worst}'s held-out max error "
                          f"(over {max_share:.0%}): not recommended")
    cost_ = [p.instructions if p.score is not None and i not in over else None for i, p in enumerate(points)]
    score = [p.score for p in points]
    front = pareto_front(cost_, score)
    rec, met = recommend([math.nan if c is None else c for c in cost_],
                         [math.nan if s is None else s for s in score], [p.flash for p in points])
    setup = {"training_rows": train.n_rows, "levels": scene.levels, "held_out": n_held, "noise_draws": noise_draws,
             "noise": sensor.noise, "units": sensor.units, "seed": seed, "fits": len(fits), "measured": len(units)}
    return TradeoffResult(sensor.name, sensor.transfer, scene, target, points, front, rec, met, warnings, notes, setup,
                          max_share, over)


# --- output --------------------------------------------------------------------------------------------

def _g(x, digits: int = 3) -> str:
    return "" if x is None else f"{x:.{digits}g}"


def _k(k) -> str:
    return k if isinstance(k, str) else f"{k:g}"


def to_csv(result: TradeoffResult) -> str:
    outs = result.scene.outputs
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["point", "k", "max_terms", "family", "refine", "precision", "style", "terms"]
               + [f"terms_{o}" for o in outs] + [f"ops_{k}" for k in OP_KINDS]
               + ["instructions", "loop_instructions", "flash", "object_flash"]
               + [f"{o}_{s}" for o in outs for s in ("max", "rms", "noisy_max", "noisy_rms")]
               + [f"{o}_share" for o in outs] + ["score", "share", "front", "recommended", "model", "note"])
    for i, p in enumerate(result.points):
        kn = p.knobs
        w.writerow([i + 1, _k(kn.k), kn.max_terms or "", kn.family, kn.refine, kn.precision, kn.style, p.terms]
                   + [p.terms_per_output.get(o, "") for o in outs] + [p.ops.get(k, "") for k in OP_KINDS]
                   + [_g(p.instructions, 6), _g(p.loop_instructions, 6), _g(p.flash, 9), _g(p.object_flash, 9)]
                   + [_g(p.errors[o][s], 6) if p.errors else "" for o in outs
                      for s in ("max", "rms", "noisy_max", "noisy_rms")]
                   + [_g(p.errors[o]["share"], 6) if p.errors else "" for o in outs]
                   + [_g(p.score, 6), _g(p.share, 6), int(i in result.front), int(i == result.recommended),
                      p.model_hash[:12], p.note])
    return buf.getvalue()


def _row(i: int, p: Point, result: TradeoffResult) -> str:
    kn = p.knobs
    mark = ("**rec** " if i == result.recommended else "") + ("front" if i in result.front else "")
    ops = "/".join(str(p.ops.get(k, 0)) for k in OP_KINDS) if p.ops else ""
    errs = " | ".join(f"{_g(p.errors[o]['rms'])} / {_g(p.errors[o]['noisy_rms'])} / {_g(p.errors[o]['noisy_max'])}"
                      if p.errors else "" for o in result.scene.outputs)
    return (f"| {i + 1} | {_k(kn.k)} | {kn.max_terms or '-'} | {kn.method} | {kn.precision} | {kn.style} | {p.terms} | "
            f"{ops} | {_g(p.instructions, 4)} | {_g(p.flash, 6)} | {errs} | {_g(p.score)} | "
            f"{'' if p.share is None else f'{p.share:.1%}'} | {mark.strip()} |"
            + (f" {p.note}" if p.note else ""))


def describe(i: int | None, result: TradeoffResult) -> str:
    if i is None:
        return "none"
    p = result.points[i]
    return (f"point {i + 1} ({p.knobs.label}): {p.terms} terms, {_g(p.instructions, 4)} instructions per estimate, "
            f"{_g(p.flash, 6) or '?'} bytes of flash, score {_g(p.score)}")


def to_markdown(result: TradeoffResult, plot: str | None = None) -> str:
    s, outs = result.setup, result.scene.outputs
    units = {o: POSE_UNITS[POSE_NAMES.index(o)] for o in outs}
    lines = [f"# Trade-off: sensor {result.sensor} ({result.transfer}), scene {result.scene.name}", ""]
    lines.append(f"Training: the scene's grid, {s['training_rows']:,} poses ({s['levels']} levels per moving "
                 "component), simulated noise-free and fitted for the sensor's noise and float rounding. "
                 f"Held-out: {s['held_out']:,} random poses in the scene's box (seed "
                 f"{s['seed']}), noise-free and with the sensor's noise ({s['noise']:g} {s['units']} rms per element, "
                 f"{s['noise_draws']} draws). {s['fits']} fits, {s['measured']} distinct builds measured.")
    lines.append("")
    lines.append("Target (RMS error with noise): " + ", ".join(f"{o} {result.target[o]:g} {units[o]}" for o in outs)
                 + ". Score = the worst output's RMS error with noise / its target; <= 1 meets the target.")
    lines.append("")
    if result.warnings:
        lines.append(f"Resolvability: sensor {result.sensor} cannot resolve everything scene {result.scene.name} asks "
                     "for (fitted anyway, as with `fit --force`):")
        lines += [f"- {w}" for w in result.warnings]
        lines.append("")
    for n in result.notes:
        lines.append(f"Note: {n}.")
        lines.append("")
    if result.over_share:
        lines.append(f"**Rounding check failed** on {len(result.over_share)} point(s): the generated C deviates from "
                     f"the double model by more than {result.max_share:.0%} of that model's held-out max error "
                     "(they are left off the front and the recommendation): points "
                     + ", ".join(str(i + 1) for i in result.over_share) + ".")
        lines.append("")
    lines.append("## Recommendation")
    lines.append("")
    if result.recommended is None:
        lines.append("No point could be measured.")
    elif result.met:
        lines.append(f"Meets the target with the fewest instructions: {describe(result.recommended, result)}.")
    else:
        lines.append(f"No point meets the target. The most accurate (scores within {ACCURACY_TIE:.0%} of the best "
                     f"taken as equal, then the fewest instructions): {describe(result.recommended, result)}.")
    lines.append("")
    lines.append("## Pareto front (instructions per estimate against score)")
    lines.append("")
    shown = set()
    for i in result.front:
        p = result.points[i]
        if (p.model_hash, p.knobs.precision, p.knobs.style) in shown:
            continue
        shown.add((p.model_hash, p.knobs.precision, p.knobs.style))
        same = [j + 1 for j in result.front if j != i and result.points[j].model_hash == p.model_hash
                and (result.points[j].knobs.precision, result.points[j].knobs.style) == (p.knobs.precision, p.knobs.style)]
        lines.append(f"- {describe(i, result)}" + (f" (the same build: points {', '.join(map(str, same))})"
                                                    if same else ""))
    lines.append("")
    if plot:
        lines.append(f"![instructions against score]({plot})")
        lines.append("")
    lines.append("## All points")
    lines.append("")
    lines.append("Ops: mul/add/div/sqrt/cbrt per estimate as the templates write them. Instructions: x86-64, inside "
                 "tm_estimate, per estimate (callgrind). Flash: bytes the estimator adds to a linked Cortex-M4F "
                 "(double, float) or Cortex-M0 (fixed) program, library code included. Errors per output: RMS "
                 "noise-free / RMS with noise / max with noise. Rounding's share: the largest deviation of this "
                 "precision's C from the double model on the noise-free held-out readings, over the double model's "
                 "max error there (worst output).")
    lines.append("")
    lines.append("| # | k | cap | family | precision | style | terms | ops | instructions | flash | "
                 + " | ".join(f"{o} [{units[o]}]" for o in outs) + " | score | rounding's share | |")
    lines.append("|" + " --- |" * (14 + len(outs) - 1))
    lines += [_row(i, p, result) for i, p in enumerate(result.points)]
    return "\n".join(lines) + "\n"


def write_outputs(result: TradeoffResult, folder: str | Path) -> tuple[list[Path], str]:
    """DIR/tradeoff.csv, DIR/tradeoff.md and (matplotlib permitting) DIR/tradeoff.png, each
    written atomically; returns the paths and the markdown."""
    from fitgen.base.fileio import write_atomic

    folder = Path(folder)
    if not folder.is_dir():
        try:
            folder.mkdir(parents=True)
        except OSError as exc:
            raise InputError(f"cannot create {folder}: {exc.strerror}") from None
    paths = [write_atomic(folder / "tradeoff.csv", to_csv(result))]
    plot = None
    try:
        from fitgen.app import plots

        paths.append(plots.tradeoff(result, folder / "tradeoff.png"))
        plot = "tradeoff.png"
    except InputError as exc:
        result.notes.append(f"no plot: {exc}")
    text = to_markdown(result, plot)
    paths.insert(1, write_atomic(folder / "tradeoff.md", text))
    return paths, text
