"""The trade-off sweep: accuracy against cost over the knobs a user can turn: penalty per term, cap
on terms, candidate family, precision, code style and refinement steps (fitgen.equations.refine: swept
on the harmonics family, in float and double, for scenes that estimate the whole pose).

One fit per (k, cap, family, refinement) on the scene's grid, simulated noise-free with the sensor; every
precision and style of that fit is then measured on held-out random poses in the scene's box
(noise-free, and with the sensor's noise in several draws) and in cost: terms, floating-point
operations by kind as the templates write them, x86-64 instructions per estimate counted by
callgrind (deterministic), and the flash the estimator adds to a Cortex-M program. For a core
(``core="uno"``): its plans (fixed point: fitgen.c.targets' multiply width), cycles per estimate on the
ATmega328P in simavr (fitgen.c.avr, N_AVR held-out inputs, each answer held against Python's bit for
bit) and the AVR program's flash; double, which it cannot run, is left out.

The score of a point is the worst output's RMS error with noise over its target (<= 1 meets the
target); the Pareto front is taken on (cost, score), the cost being instructions (cycles on a core),
and the recommended point is the cheapest that meets the target (ties: less flash); fitgen.c.tradeoff_choice
chooses, and leaves out points that estimate an output no better than a constant.
"""

from __future__ import annotations

import itertools
import math
import shutil
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fitgen.base.errors import InputError
from fitgen.c.codegen import STYLES
from fitgen.c.targets import TARGETS, get_target
from fitgen.c.tradeoff_choice import constant_outputs, pareto_front, recommend
from fitgen.equations.fixedpoint import build_fixed
from fitgen.equations.inputscale import sensor_input_scale as fixed_scale
from fitgen.equations.model import Model
from fitgen.equations.rounding import PRECISIONS
from fitgen.equations.terms import FAMILIES, HARMONIC_DEGREE
from fitgen.fitting.family import rounding_checked
from fitgen.fitting.fit import FitSettings, fit_model, rows_needed
from fitgen.physics.pose import POSE_NAMES
from fitgen.physics.scenes import Scene, unresolved_warnings
from fitgen.physics.simulate import pose_rng, random_poses, simulate
from fitgen.physics.transfer import missing_noise

K_VALUES = ("aic", "bic", 6.0)
CAPS = (None, 20, 8)
FAMILY_NAMES = tuple(FAMILIES)
# families fixed point cannot generate: their harmonic terms divide (a family with roots may fit without them)
NO_FIXED = tuple(f for f in FAMILIES if HARMONIC_DEGREE.get(f))
REFINE_STEPS = (0, 1)
REFINED_FAMILIES = ("harmonics",)  # the refinement is swept on these (docs/refine.md measures it on them)
FIXED_STYLE = "-"  # the fixed-point header is straight-line code: the style knob does not apply
OP_KINDS = ("mul", "add", "div", "sqrt", "cbrt")
# Cortex-M core whose flash is reported, per precision (see fitgen.c.cost.ARM_CORES)
CORE_OF = {"double": "cortex-m4f", "float": "cortex-m4f", "fixed": "cortex-m0"}
N_HELD = 1000
NOISE_DRAWS = 5
N_AVR = 20  # held-out inputs per build in simavr (the cycles vary by well under 1 % between inputs)


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
    def fit_label(self) -> str:
        """The knobs of the fit alone (:attr:`fit_key`'s): ``aic cap=- harmonics``."""
        k = self.k if isinstance(self.k, str) else f"k={self.k:g}"
        return f"{k} cap={self.max_terms or '-'} {self.method}"

    @property
    def label(self) -> str:
        return f"{self.fit_label} {self.precision} {self.style}"

    def settings(self) -> FitSettings:
        k = 2.0 if self.k == "aic" else self.k
        return FitSettings.family(self.family, k=k, max_terms=self.max_terms, refine=self.refine)


def _styles(precision: str) -> tuple[str, ...]:
    return (FIXED_STYLE,) if precision == "fixed" else STYLES


def left_out(k: Knobs) -> str:
    """The rule that leaves ``k`` out of every sweep, in words; '' when a sweep can run it."""
    if k.precision == "fixed" and k.family in NO_FIXED:
        return f"fixed point has no {k.family} family"
    if k.precision == "fixed" and k.refine:
        return "fixed point has no refinement"
    if k.refine and k.family not in REFINED_FAMILIES:
        return f"the refinement is swept on the {' and '.join(REFINED_FAMILIES)} family only"
    return ""


def _possible(points: list[Knobs]) -> list[Knobs]:
    return [k for k in points if not left_out(k)]


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
    return _possible(combinations(k, max_terms, family, precision, style, refine))


def combinations(k=None, max_terms=None, family=None, precision=None, style=None, refine=None) -> list[Knobs]:
    """:func:`grid_from`'s points before the rules (:func:`left_out`) leave any out."""
    ks, caps = k or K_VALUES, max_terms or CAPS
    fams, precs, styles = family or FAMILY_NAMES, precision or PRECISIONS, style or STYLES
    return [Knobs(kk, cap, fam, p, s, r)
            for kk, cap, fam, p, r in itertools.product(ks, caps, fams, precs, refine or REFINE_STEPS)
            for s in (_styles(p) if p == "fixed" else styles)]


def default_target(outputs: tuple[str, ...]) -> dict[str, float]:
    """The accuracy to meet per output when none is given: fitgen.physics.observe.DEFAULT_ACCURACY."""
    from fitgen.physics.observe import DEFAULT_ACCURACY

    return {o: DEFAULT_ACCURACY[o] for o in outputs}


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
    flash: int | None = None  # bytes the estimator adds to a linked Cortex-M program (core: the AVR program's)
    cycles: float | None = None  # core: cycles per estimate on it (simavr), the mean over N_AVR inputs
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
    core: str | None = None  # the costs are cycles on this core (fitgen.c.targets), else x86 instructions
    constant: list[int] = field(default_factory=list)  # points that estimate some output no better than a constant
    given: tuple = ()  # the command's sensor options as typed (--sensor's value, --transfer ...), to reproduce a point
    scene_given: str | None = None  # --scene as typed (a file's path), to reproduce a point

    def cost(self, p: Point) -> float | None:
        """The point's cost: cycles per estimate on the core, else instructions."""
        return p.cycles if self.core else p.instructions


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
                 scale: tuple[float, float] | None = None, core: str | None = None, runner: Path | None = None):
        self.X, self.Y, self.Xn, self.Yn = held_inputs, held_truth, noisy_inputs, noisy_truth
        self.outputs, self.work, self.have_arm, self.scale = outputs, work, have_arm, scale
        self.core, self.runner = core, runner
        self.mul_bits = TARGETS[core].mul_bits if core else 32

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
            lsb, offset = self.scale
            fm = build_fixed(model, lsb, offset, self.mul_bits)
            res = {"ops": fixed_ops(fm)}
            # the numpy model of the integer arithmetic: the C's integers exactly, on the inputs' codes
            pred = fm.to_real(fm.predict_codes(fm.codes_of(both))[0])
            header, bench_inputs = {"input_lsb": lsb, "input_offset": offset, "target": self.core}, \
                fm.codes_of(self.X).astype(float)
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
        if self.core:
            res["cycles"], res["flash"] = self._on_core(model, precision, style, bench_inputs[:N_AVR], folder / "avr")
        elif self.have_arm:
            a = cost.arm_sizes(model, style, precision, False, folder / "arm", cost.ARM_CORES[CORE_OF[precision]],
                               **header)
            res["flash"], res["object_flash"] = a["linked"], a["text"] + a["data"]
        return res


    def _on_core(self, model, precision, style, inputs, folder) -> tuple[float, int]:
        """(cycles per estimate, flash of the program less its inputs) on the ATmega328P; a result that is
        not Python's bit for bit is a RuntimeError (the point is then not measured)."""
        from fitgen.c.avr import run_on_avr

        if precision == "fixed":
            lsb, offset = self.scale
            run = run_on_avr(model, inputs, "fixed", input_lsb=lsb, input_offset=offset, mul_bits=self.mul_bits,
                             workdir=folder, runner=self.runner)
            fm = build_fixed(model, lsb, offset, self.mul_bits)
            want, status = fm.predict_codes(inputs)
        else:
            run = run_on_avr(model, inputs, "float", style, workdir=folder, runner=self.runner)
            want, status = model.predict(inputs.astype(np.float32).astype(float), with_status=True, precision="float")
        if not (np.array_equal(run.outputs, want) and np.array_equal(run.status, status)):
            raise RuntimeError(f"the {self.core} build's results differ from Python's")
        return float(np.mean(run.cycles)), run.flash - 4 * inputs.size


def fixed_ops(fm) -> dict:
    """Integer operations of a fixed-point plan, by the float kinds: a product (and its shift) is a
    mul, a reciprocal a div, a term a mul and an add."""
    kinds = [op.kind for op in fm.ops]
    return {"mul": kinds.count("mul") + kinds.count("term"), "add": kinds.count("term"), "div": kinds.count("recip"),
            "sqrt": 0, "cbrt": 0}


def sweep(sensor, scene: Scene, grid: list[Knobs], *, target: dict | None = None, seed: int = 0,
          n_held: int = N_HELD, noise_draws: int = NOISE_DRAWS, jobs: int = 2, progress=None,
          max_share: float = 0.05, core: str | None = None) -> TradeoffResult:
    """Fit, build and measure every point of ``grid`` for ``sensor`` on ``scene``.

    A point whose rounding adds more than ``max_share`` of its model's held-out max error is
    listed in ``over_share`` and is neither on the front nor recommended. ``core`` ("uno"): costs in
    cycles on it, its plans, its precisions only (fitgen.c.targets).

    ``progress(note, total)`` is called once per fit and once per distinct build measured; ``total``: their
    number (known in full once the fits are done). Needs gcc and valgrind; the flash
    figures need arm-none-eabi-gcc/size/nm (left empty, with a note, without them).
    """
    if shutil.which("valgrind") is None:
        raise InputError("valgrind not found: the instruction counts need it (apt-get install valgrind)")
    if not sensor.noise > 0:  # said as the sweep's need: observe's words name a --noise the sweep has not
        raise InputError(f"{missing_noise(sensor)}: the sweep measures accuracy with the device's reading noise; "
                         "add it to the file")
    outputs = scene.outputs
    target = default_target(outputs) if target is None else dict(target)
    notes: list[str] = []
    warnings = unresolved_warnings(sensor, scene, accuracy=target)
    if tuple(outputs) != POSE_NAMES and any(k.refine for k in grid):
        notes.append(f"no refinement: it estimates the whole pose, and scene {scene.name} asks for "
                     f"{','.join(outputs)} only")
        grid = [k for k in grid if not k.refine]
        if not grid:
            raise InputError(f"nothing to sweep: the refinement estimates the whole pose, and scene {scene.name} "
                             f"asks for {','.join(outputs)} only")

    if core is not None:
        grid = _for_core(core, grid, notes)
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
    if not have_arm and core is None:
        notes.append("flash sizes skipped: arm-none-eabi-gcc/size/nm not found")

    # training: the scene's grid, noise-free; held-out: random poses in its box, seeded
    taught = scene.with_rows(rows_needed(sensor.n_elements))  # a ring of ten elements: more than press's 21 levels
    train = simulate(sensor, taught.poses(), provenance={"scene": scene.name})
    poses = random_poses(n_held, scene.ranges, pose_rng(seed))
    cols = [POSE_NAMES.index(o) for o in outputs]
    clean = simulate(sensor, poses, seed=seed)
    noisy = [simulate(sensor, poses, noise=sensor.noise, seed=seed + 1 + i) for i in range(noise_draws)]
    X, Y = clean.inputs, poses[:, cols]
    Xn, Yn = np.vstack([d.inputs for d in noisy]), np.tile(Y, (noise_draws, 1))

    fits: dict[tuple, Model] = {}
    n_fits = len({kn.fit_key for kn in grid})
    for kn in grid:
        if kn.fit_key not in fits:
            # what `fitgen fit` gives with these knobs: fitted again where its rounding would matter on the device
            fits[kn.fit_key], record = rounding_checked(lambda s: (fit_model(train, outputs, s, sensor=sensor), {}),
                                                        train, kn.settings(), sensor)
            if "rounding" in record:
                notes.append(f"fit {kn.fit_label}: {record['rounding']['why']}")
            if progress:  # the total grows to the builds once the fits say how many distinct ones there are
                progress(f"fit {kn.label}", n_fits + len(grid))

    points = [Point(kn) for kn in grid]
    units: dict[tuple, list[int]] = {}
    for i, p in enumerate(points):
        m = fits[p.knobs.fit_key]
        p.model_hash = m.sha256
        p.terms_per_output = {e.name: len(e.terms) for e in m.equations}
        p.terms = sum(p.terms_per_output.values())
        units.setdefault((m.sha256, p.knobs.precision, p.knobs.style), []).append(i)
    total, unmeasured = n_fits + len(units), 0

    with tempfile.TemporaryDirectory(prefix="fitgen-tradeoff-") as tmp:
        runner = None
        if core is not None:
            from fitgen.c.avr import build_runner

            (Path(tmp) / "runner").mkdir()
            runner = build_runner(Path(tmp) / "runner")
        measure = _Measure(X, Y, Xn, Yn, outputs, Path(tmp), have_arm, scale, core, runner)

        def one(item):
            n, ((_, precision, style), idx) = item
            model = fits[points[idx[0]].knobs.fit_key]
            try:
                return idx, measure(model, precision, style, f"u{n}"), ""
            except (InputError, RuntimeError) as exc:
                return idx, None, str(exc).splitlines()[0][:200]

        with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
            for idx, res, err in pool.map(one, enumerate(units.items())):
                unmeasured += res is None
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
                    progress(f"built {points[idx[0]].knobs.label}", total)

    over = [i for i, p in enumerate(points) if p.share is not None and p.share > max_share]
    for i in over:
        worst = max(outputs, key=lambda o: points[i].errors[o]["share"])
        points[i].note = (f"rounding adds {points[i].share:.1%} of {worst}'s held-out max error "
                          f"(over {100 * max_share:.3g} %): not recommended")
    constant = constant_outputs(points, outputs, Y, over)
    cost_ = [(p.cycles if core else p.instructions) if p.score is not None and i not in over + constant else None
             for i, p in enumerate(points)]
    score = [p.score for p in points]
    front = pareto_front(cost_, score)
    rec, met = recommend([math.nan if c is None else c for c in cost_],
                         [math.nan if s is None else s for s in score], [p.flash for p in points])
    setup = {"training_rows": train.n_rows, "levels": taught.levels, "held_out": n_held, "noise_draws": noise_draws,
             "noise": sensor.noise, "units": sensor.units, "seed": seed, "fits": len(fits),
             "measured": len(units) - unmeasured}
    return TradeoffResult(sensor.name, sensor.transfer, scene, target, points, front, rec, met, warnings, notes, setup,
                          max_share, over, core, constant)


def _for_core(core: str, grid: list[Knobs], notes: list[str]) -> list[Knobs]:
    """The points ``core`` can run (an InputError when none), with a note of what it cannot."""
    t = get_target(core)
    left = [k for k in grid if k.precision in t.precisions]
    dropped = sorted({k.precision for k in grid} - set(t.precisions))
    if dropped:
        notes.append(f"no {', '.join(dropped)} on {core}: {t.why}")
    if not left:
        raise InputError(f"nothing to sweep: {core} takes --precision {' or '.join(t.precisions)}")
    if t.progmem and any(k.refine for k in left):  # as fitgen.c.codegen refuses it for such a core
        notes.append(f"no refinement on {core}: its forward model and solve do not fit the {t.core}")
        left = [k for k in left if not k.refine]
        if not left:
            raise InputError(f"nothing to sweep: a refinement does not fit the {core}; sweep --refine 0")
    notes.append(f"costs on {core} ({t.core}): cycles per estimate in simavr over {N_AVR} held-out inputs, each "
                 f"answer Python's bit for bit; flash: the AVR program less its inputs"
                 + ("; fixed point in its plan for a 16-bit multiply" if t.mul_bits == 16 else ""))
    return left
