"""Estimators a user might pick instead of ours, on one scale: accuracy (noise-free and with the
sensor's noise) against cost on the device (issue 13, parts 2 and 3).

Run:

    python bench/estimators.py > out.md                  # tables on stdout, progress on stderr
    python bench/estimators.py --plot docs/img > out.md  # and docs/img/estimators-front.png

Needs the `compare` extra (scikit-learn, abess: `pip install -e '.[compare]'`), gcc and valgrind
(instruction counts), arm-none-eabi-gcc/size with newlib (flash) and matplotlib for --plot.
Without scikit-learn it prints one line and exits 2.

Setting (deterministic), per layout (`paper`, `ring-vertical`; transfer raw):

- Training: the paper-sim grid (1,875 poses) simulated noise-free.
- Held out: 2,000 random poses uniform in the paper-sim box (pose seed 2026); noise-free, and
  with the sensor's noise (draws with noise seeds 1..5, pooled).
- Floor: the Cramer-Rao bound (fitgen.physics.observe.analyse, the sensor's noise, all five components)
  at each held-out pose, RMS over the poses.

Methods:

1. `ours`: fit_model(train) with the default FitSettings() (noise- and float-aware stepwise AIC).
   `ours, harmonics`: the same search with the harmonics family (FitSettings.family("harmonics"):
   the paper's powers and monomials up to degree 3 of the ring's harmonics), AIC, BIC and caps.
   `+ refine k`: those equations, then k Gauss-Newton steps on a forward model fitted to the same
   grid (fitgen.equations.refine; `--refine k`), all in the same float C.
2. `lasso-aic`, `lasso-bic`: scikit-learn LassoLarsIC per output on the same candidate columns
   (fitgen.equations.terms.candidate_terms + design_matrix; columns standardised, coefficients mapped back
   to raw columns and intercept); thx, thy get the d-terms from the same method's stage-1
   displacement equations on the training rows, as fit_model does. `relaxed`: the lasso's terms
   refitted by least squares.
3. `abess`: best subset (abess.linear.LinearRegression) per output with support size = ours' term
   count for that output; same candidates, same conversion.
4. `mlp`: scikit-learn MLPRegressor (standardised inputs and outputs, adam, random_state 0), the
   ReSkin/AnySkin kind of estimator; its forward pass written here as C (float, static const
   weights), checked against sklearn's predict on the held-out inputs, and run as deployed (the
   float C on the noisy held-out readings).
5. `gauss-newton`: model-based inversion on the sensor's own field model: from rest, k steps of
   Gauss-Newton (central-difference Jacobian, pseudo-inverse step, pose clipped into the paper-sim
   box), k = 1, 3, 10; double, Python, not compiled: its cost is given as field-model evaluations
   (of all elements) per estimate.

The regression models (1-3) become fitgen.equations.model.Model objects, so cost is measured exactly like
ours: callgrind instructions per estimate inside tm_estimate of the float unrolled C (fitgen.c.cost)
and the Cortex-M4F flash it adds to a newlib program (fitgen.c.cost.arm_sizes, `linked`; `.o` is the
object's text + data). Their deployed accuracy is Model.predict(precision="float") (bit-identical to
the float C) on the noisy held-out readings; noise-free: Model.predict in double. The MLP's C goes
through the same bench program and the same link, so its figures are on the same scale.
"""

from __future__ import annotations

import shlex
import subprocess
import sys
import tempfile
import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

try:
    import sklearn  # noqa: F401
except ImportError:
    print("bench/estimators.py needs scikit-learn: pip install -e '.[compare]'", file=sys.stderr)
    sys.exit(2)

from sklearn.exceptions import ConvergenceWarning
from sklearn.linear_model import LassoLarsIC
from sklearn.neural_network import MLPRegressor

from fitgen.base.errors import InputError
from fitgen.fitting.fit import FitSettings, fit_model
from fitgen.equations.model import Equation, Model
from fitgen.physics.observe import jacobian
from fitgen.physics.pose import POSE_NAMES, field_readings
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import DEFAULT_RANGES, PAPER_GRIDS, grid_poses, pose_rng, random_poses, simulate
from fitgen.equations.terms import DISPLACEMENTS, ROTATIONS, candidate_terms, design_matrix
from fitgen.physics.transfer import apply_transfer
from fitgen.c import cost
from fitgen.c.compiled import compile_checked
from benchutil import START, cramer_rao_floor, fmt, log, parser, stats, table

try:
    from abess.linear import LinearRegression as AbessLinear
    ABESS_ERROR = ""
except Exception as exc:  # noqa: BLE001 - any failure to import means: skip it, say why
    AbessLinear = None
    ABESS_ERROR = f"{type(exc).__name__}: {exc}"

LAYOUTS = ("paper", "ring-vertical")
TRANSFER = "raw"
POSE_SEED = 2026
N_HELD = 2000
NOISE_DRAWS = 5
STYLE = "unrolled"
GN_ITERS = (1, 3, 10)
# the MLPs: name, hidden layers, activation
MLPS = (("mlp 64-64 tanh", (64, 64), "tanh"), ("mlp 16-16 tanh", (16, 16), "tanh"))
MLP_MAX_ITER = 3000
OURS_VARIANTS = (("ours, BIC", FitSettings(k="bic")), ("ours, max 25 terms", FitSettings(max_terms=25)),
                 ("ours, max 10 terms", FitSettings(max_terms=10)))
# the same search with the ring's harmonic monomials among the candidates (fitgen.equations.terms.Harmonics)
HARMONIC_VARIANTS = (("ours, harmonics (AIC)", FitSettings.family("harmonics")),
                     ("ours, harmonics, BIC", FitSettings.family("harmonics", k="bic")),
                     ("ours, harmonics, max 30 terms", FitSettings.family("harmonics", max_terms=30)),
                     ("ours, harmonics, max 15 terms", FitSettings.family("harmonics", max_terms=15)),
                     ("ours, harmonics, max 8 terms", FitSettings.family("harmonics", max_terms=8)))
# the equations, then Gauss-Newton steps on a forward model fitted to the same grid (fitgen.equations.refine)
REFINE_VARIANTS = (("ours, harmonics, max 30 + refine 1", FitSettings.family("harmonics", max_terms=30, refine=1)),
                   ("ours, harmonics, max 30 + refine 2", FitSettings.family("harmonics", max_terms=30, refine=2)),
                   ("ours, harmonics, max 15 + refine 1", FitSettings.family("harmonics", max_terms=15, refine=1,
                                                                             refine_terms=15)))


class Result:
    """One estimator on one layout: its predictions' errors and its cost."""

    def __init__(self, name: str, family: str, terms=None, model: Model | None = None):
        self.name, self.family, self.terms, self.model = name, family, terms, model
        self.clean = self.noisy = None  # (max, rms) per output
        self.instructions = self.flash = self.obj = None
        self.evaluations = None  # field-model evaluations per estimate (inversion)
        self.note = ""

    @property
    def worst_d(self) -> float:
        return float(np.max(self.noisy[1][:3]))

    @property
    def worst_th(self) -> float:
        return float(np.max(self.noisy[1][3:]))


# --- linear models on our candidates -----------------------------------------------------------------

def standardise(X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    mu, sd = X.mean(axis=0), X.std(axis=0)
    sd = np.where(sd > 0, sd, 1.0)
    return (X - mu) / sd, mu, sd


def raw_equation(name: str, cands, beta_std: np.ndarray, icpt_std: float, mu, sd) -> Equation:
    """An Equation in raw columns from coefficients of standardised columns (zeros dropped)."""
    beta = beta_std / sd
    keep = np.flatnonzero(beta_std != 0)
    intercept = float(icpt_std - beta @ mu)
    return Equation(name, intercept, tuple(cands[j] for j in keep), tuple(float(beta[j]) for j in keep))


def refit_ls(Xs: np.ndarray, y: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, float]:
    """Least squares on the standardised columns ``keep`` with an intercept: (beta over all, intercept)."""
    A = np.column_stack([np.ones(len(y)), Xs[:, keep]])
    sol = np.linalg.lstsq(A, y, rcond=None)[0]
    beta = np.zeros(Xs.shape[1])
    beta[keep] = sol[1:]
    return beta, float(sol[0])


def fit_linear(train, selector, name: str) -> Model:
    """Two stages as fit_model: displacements on v-terms, rotations with the d-terms of this method's
    own stage-1 equations. ``selector(X_std, y, output) -> (beta_std, intercept_std)``."""
    v = train.inputs
    lo, hi = v.min(axis=0), v.max(axis=0)
    positive = lo > 0
    eqs = {}
    d = None
    for o in POSE_NAMES:
        if o in ROTATIONS and d is None:
            d = Model(lo, hi, tuple(eqs[x] for x in DISPLACEMENTS)).predict(v)
        cands = candidate_terms(v.shape[1], o, d_terms=o in ROTATIONS, positive=positive)
        X = design_matrix(cands, v, d if o in ROTATIONS else None)
        Xs, mu, sd = standardise(X)
        beta, icpt = selector(Xs, train.target(o), o)
        eqs[o] = raw_equation(o, cands, beta, icpt, mu, sd)
    return Model(lo, hi, tuple(eqs[o] for o in POSE_NAMES), train.meta.get("units", "mT"),
                 {"method": name})


def lasso_selector(criterion: str, relaxed: bool, info: dict):
    """``info[output]``: the LARS path's length, the criterion's pick on it, whether LARS stopped early."""
    def sel(Xs, y, o):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ConvergenceWarning)
            m = LassoLarsIC(criterion=criterion, fit_intercept=True, max_iter=2000).fit(Xs, y)
        early = any("Early stopping the lars path" in str(w.message) for w in caught)
        info[o] = (len(m.alphas_), int(np.argmin(m.criterion_)) + 1, early)
        beta, icpt = m.coef_.copy(), float(m.intercept_)
        if relaxed:
            beta, icpt = refit_ls(Xs, y, np.flatnonzero(beta))
        return beta, icpt
    return sel


def abess_selector(sizes: dict):
    def sel(Xs, y, o):
        m = AbessLinear(support_size=[sizes[o]])
        m.fit(Xs, y)
        beta = np.asarray(m.coef_, dtype=float).ravel()
        # abess's coefficients are least squares on its support; refit to be sure they are, here too
        return refit_ls(Xs, y, np.flatnonzero(beta))
    return sel


# --- the MLP and its C ------------------------------------------------------------------------------

def c_float(x: float) -> str:
    f = np.float32(x)
    text = repr(float(f)) if f == f else "0.0"
    if "e" not in text and "." not in text:
        text += ".0"
    return text + "f"


def c_array(name: str, values: np.ndarray) -> str:
    vals = np.asarray(values, dtype=float)
    dims = f"[{vals.size}]"  # flat, row-major
    flat = vals.ravel()
    body = ",\n    ".join(", ".join(c_float(x) for x in flat[i:i + 8]) for i in range(0, flat.size, 8))
    return f"static const float {name}{dims} = {{\n    {body}\n}};"


MLP_HEADER = """/* tm_model.h: a multilayer perceptron {sizes}, {act}, float; generated by bench/estimators.py */
#ifndef TM_MODEL_H
#define TM_MODEL_H
#include <math.h>

#define TM_N_INPUTS {n_in}
#define TM_N_OUTPUTS {n_out}
typedef float tm_input;
typedef float tm_output;

#ifndef TM_API
#define TM_API static
#endif

{arrays}

TM_API int tm_estimate(const tm_input in[TM_N_INPUTS], tm_output out[TM_N_OUTPUTS])
{{
    float a[{width}], b[{width}];
    int i, j;
    for (i = 0; i < TM_N_INPUTS; ++i) {{
        a[i] = (in[i] - tm_x_mean[i]) * tm_x_inv_sd[i];
    }}
{layers}
    for (j = 0; j < TM_N_OUTPUTS; ++j) {{
        out[j] = {last}[j] * tm_y_sd[j] + tm_y_mean[j];
    }}
    return 0;
}}
#endif
"""

MLP_LAYER = """    for (j = 0; j < {n_out}; ++j) {{
        float s = tm_b{k}[j];
        for (i = 0; i < {n_in}; ++i) {{
            s += tm_w{k}[j * {n_in} + i] * {src}[i];
        }}
        {dst}[j] = {act};
    }}
"""

C_RUNNER = r"""
#include <stdio.h>
#include <stdlib.h>
#include "tm_model.h"
/* usage: run INPUTS N OUTPUTS: N rows of TM_N_INPUTS doubles in, N rows of TM_N_OUTPUTS floats out */
int main(int argc, char **argv)
{
    FILE *fi, *fo;
    long n, r;
    int j;
    double raw[TM_N_INPUTS];
    tm_input in[TM_N_INPUTS];
    tm_output out[TM_N_OUTPUTS];
    if (argc < 4) {
        return 2;
    }
    fi = fopen(argv[1], "rb");
    fo = fopen(argv[3], "wb");
    n = atol(argv[2]);
    if (fi == NULL || fo == NULL) {
        return 2;
    }
    for (r = 0; r < n; ++r) {
        if (fread(raw, sizeof raw, 1, fi) != 1) {
            return 3;
        }
        for (j = 0; j < TM_N_INPUTS; ++j) {
            in[j] = (tm_input)raw[j];
        }
        tm_estimate(in, out);
        fwrite(out, sizeof out, 1, fo);
    }
    fclose(fi);
    fclose(fo);
    return 0;
}
"""


class MLP:
    def __init__(self, hidden: tuple[int, ...], activation: str):
        self.hidden, self.activation = hidden, activation

    def fit(self, X: np.ndarray, Y: np.ndarray) -> "MLP":
        self.x_mean, self.x_sd = X.mean(axis=0), X.std(axis=0)
        self.y_mean, self.y_sd = Y.mean(axis=0), Y.std(axis=0)
        self.net = MLPRegressor(hidden_layer_sizes=self.hidden, activation=self.activation, solver="adam",
                                max_iter=MLP_MAX_ITER, tol=1e-6, n_iter_no_change=20, random_state=0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            self.net.fit((X - self.x_mean) / self.x_sd, (Y - self.y_mean) / self.y_sd)
        return self

    def predict(self, X: np.ndarray) -> np.ndarray:
        return self.net.predict((X - self.x_mean) / self.x_sd) * self.y_sd + self.y_mean

    @property
    def n_weights(self) -> int:
        return sum(w.size for w in self.net.coefs_) + sum(b.size for b in self.net.intercepts_)

    def header(self) -> str:
        W, B = self.net.coefs_, self.net.intercepts_
        arrays = [c_array("tm_x_mean", self.x_mean), c_array("tm_x_inv_sd", 1.0 / self.x_sd),
                  c_array("tm_y_mean", self.y_mean), c_array("tm_y_sd", self.y_sd)]
        layers = []
        bufs = ["a", "b"]
        for k, (w, b) in enumerate(zip(W, B), start=1):
            arrays += [c_array(f"tm_w{k}", w.T), c_array(f"tm_b{k}", b)]
            src, dst = bufs[(k - 1) % 2], bufs[k % 2]
            hidden = k < len(W)
            act = "s" if not hidden else ("tanhf(s)" if self.activation == "tanh" else "(s > 0.0f ? s : 0.0f)")
            layers.append(MLP_LAYER.format(k=k, n_in=w.shape[0], n_out=w.shape[1], src=src, dst=dst, act=act))
        sizes = "-".join(str(n) for n in (W[0].shape[0],) + self.hidden + (W[-1].shape[1],))
        width = max([W[0].shape[0]] + list(self.hidden) + [W[-1].shape[1]])
        return MLP_HEADER.format(sizes=sizes, act=self.activation, n_in=W[0].shape[0], n_out=W[-1].shape[1],
                                 arrays="\n".join(arrays), width=width, layers="".join(layers),
                                 last=bufs[len(W) % 2])

    def run_c(self, X: np.ndarray, folder: Path) -> np.ndarray:
        """The float C's outputs for rows of X (inputs rounded to float as the C's caller would)."""
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "tm_model.h").write_text(self.header())
        (folder / "run.c").write_text(C_RUNNER)
        binary = folder / "run"
        compile_checked("gcc", [folder / "run.c"], binary, folder)
        np.ascontiguousarray(X, dtype=np.float64).tofile(folder / "in.f64")
        cost.run([str(binary), str(folder / "in.f64"), str(len(X)), str(folder / "out.f32")])
        return np.fromfile(folder / "out.f32", dtype=np.float32).reshape(len(X), -1).astype(float)

    def instructions(self, inputs: np.ndarray, folder: Path) -> float:
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "tm_model.h").write_text(self.header())
        (folder / "bench.c").write_text(cost.C_BENCH)
        binary = folder / "bench"
        compile_checked("gcc", [folder / "bench.c"], binary, folder)
        inp = cost.write_inputs(inputs, folder / "inputs.f64")
        return cost.instruction_counts(binary, inp, folder, mix=False, repeat=False)["fn"]

    def arm_sizes(self, folder: Path, cc: str = cost.ARM_CC) -> dict:
        """As fitgen.c.cost.arm_sizes, for this header: object text+data and the linked flash it adds."""
        d = Path(folder)
        d.mkdir(parents=True, exist_ok=True)
        (d / "tm_model.h").write_text(self.header())
        (d / "call.c").write_text(cost.C_ARM)
        obj = d / "call.o"
        compile_checked(cc, [d / "call.c"], obj, d, link=False)
        text, data, _ = cost._size(obj)
        (d / "main.c").write_text(cost.C_ARM_MAIN)
        (d / "empty.c").write_text(cost.C_ARM_EMPTY)
        link = shlex.split(cc) + ["-O2", "-specs=nosys.specs", "-Wl,--gc-sections", "-I", str(d)]
        cost.run(link + [str(d / "main.c"), str(obj), "-o", str(d / "full.elf"), "-lm"])
        cost.run(link + [str(d / "empty.c"), "-o", str(d / "empty.elf")])
        sizes = [sum(cost._size(d / elf)[:2]) for elf in ("full.elf", "empty.elf")]
        return {"obj": text + data, "linked": sizes[0] - sizes[1]}


# --- model-based inversion ----------------------------------------------------------------------------

def gauss_newton(sensor, y: np.ndarray, iters: tuple[int, ...]) -> dict[int, np.ndarray]:
    """Poses from readings y (P, N) by Gauss-Newton on the field model, from rest; snapshots at ``iters``."""
    lo = np.array([DEFAULT_RANGES[n][0] for n in POSE_NAMES])
    hi = np.array([DEFAULT_RANGES[n][1] for n in POSE_NAMES])
    p = np.zeros((len(y), 5))
    out = {}
    for k in range(1, max(iters) + 1):
        f = apply_transfer(sensor, field_readings(sensor, p), adc_bits=0)
        J = jacobian(sensor, p)  # (P, N, 5), 10 evaluations
        step = np.einsum("pij,pj->pi", np.linalg.pinv(J, rcond=1e-10), y - f)
        p = np.clip(p + step, lo, hi)
        if k in iters:
            out[k] = p.copy()
    return out


# --- one layout ----------------------------------------------------------------------------------------

class Layout:
    def __init__(self, layout: str):
        self.name = layout
        self.sensor = load_sensor(layout).with_transfer(TRANSFER)
        self.train = simulate(self.sensor, grid_poses(PAPER_GRIDS["paper-sim"]))
        self.poses = random_poses(N_HELD, DEFAULT_RANGES, pose_rng(POSE_SEED))
        self.clean = simulate(self.sensor, self.poses).inputs
        self.noisy = np.vstack([simulate(self.sensor, self.poses, noise=self.sensor.noise, seed=s).inputs
                                for s in range(1, NOISE_DRAWS + 1)])
        self.truth_noisy = np.tile(self.poses, (NOISE_DRAWS, 1))
        self.results: list[Result] = []
        self.notes: list[str] = []

    def floor(self) -> None:
        f = cramer_rao_floor(self.sensor, self.poses)
        self.floor_rms, self.floor_median = f["rms"], f["median"]

    def judge_model(self, r: Result) -> None:
        r.clean = stats(r.model.predict(self.clean) - self.poses)
        r.noisy = stats(r.model.predict(self.noisy, precision="float") - self.truth_noisy)
        r.terms = [len(e.terms) for e in r.model.equations]
        # what float rounding alone does (noise-free), and what the noise does in double: to tell them apart
        r.rounding = np.abs(r.model.predict(self.clean, precision="float") - r.model.predict(self.clean)).max(axis=0)
        r.noisy_double = stats(r.model.predict(self.noisy) - self.truth_noisy)

    def fit_linear(self) -> None:
        t = time.monotonic()
        ours = Result("ours (stepwise AIC, default)", "ours", model=fit_model(self.train, sensor=self.sensor))
        self.results.append(ours)
        # cheaper points of our own front: BIC's penalty, and caps on the terms per output
        for name, settings in OURS_VARIANTS:
            self.results.append(Result(name, "ours", model=fit_model(self.train, settings=settings,
                                                                     sensor=self.sensor)))
        for name, settings in HARMONIC_VARIANTS:
            self.results.append(Result(name, "harmonics", model=fit_model(self.train, settings=settings,
                                                                          sensor=self.sensor)))
        for name, settings in REFINE_VARIANTS:
            self.results.append(Result(name, "refine", model=fit_model(self.train, settings=settings,
                                                                       sensor=self.sensor)))
        log(f"{self.name}: ours fitted, {1 + len(OURS_VARIANTS) + len(HARMONIC_VARIANTS) + len(REFINE_VARIANTS)} settings "
            f"({time.monotonic() - t:.1f} s)")
        sizes = {e.name: len(e.terms) for e in ours.model.equations}
        for crit in ("aic", "bic"):
            for relaxed in (False, True):
                t = time.monotonic()
                name = f"lasso-{crit}" + (", relaxed" if relaxed else "")
                info: dict = {}
                m = fit_linear(self.train, lasso_selector(crit, relaxed, info), name)
                r = Result(name, "lasso", model=m)
                r.note = ("LARS path points, the criterion's pick (1-based), LARS stopped early on collinear "
                          "columns: " + ", ".join(f"{o} {n}, {k}{', early stop' if e else ''}"
                                                  for o, (n, k, e) in info.items()))
                self.results.append(r)
                log(f"{self.name}: {name} fitted ({time.monotonic() - t:.1f} s)")
        if AbessLinear is None:
            self.notes.append(f"abess not run: {ABESS_ERROR}")
        else:
            t = time.monotonic()
            try:
                m = fit_linear(self.train, abess_selector(sizes), "abess")
                self.results.append(Result("abess (ours' term counts)", "abess", model=m))
            except Exception as exc:  # noqa: BLE001 - report and go on
                self.notes.append(f"abess failed: {type(exc).__name__}: {str(exc)[:200]}")
            log(f"{self.name}: abess fitted ({time.monotonic() - t:.1f} s)")
        for r in self.results:
            self.judge_model(r)

    def fit_mlps(self, work: Path) -> None:
        Y = np.column_stack([self.train.target(o) for o in POSE_NAMES])
        for name, hidden, act in MLPS:
            t = time.monotonic()
            mlp = MLP(hidden, act).fit(self.train.inputs, Y)
            r = Result(name, "mlp")
            r.mlp = mlp
            r.terms = [mlp.n_weights]
            c_out = mlp.run_c(np.vstack([self.clean, self.noisy]), work / f"mlp{len(self.results)}")
            n = len(self.clean)
            dev = np.abs(c_out[:n] - mlp.predict(self.clean)).max(axis=0)
            r.clean = stats(mlp.predict(self.clean) - self.poses)
            r.noisy = stats(c_out[n:] - self.truth_noisy)
            r.note = (f"{mlp.net.n_iter_} epochs; float C against sklearn predict on the noise-free held-out "
                      f"inputs: max deviation " + ", ".join(f"{o} {fmt(x)}" for o, x in zip(POSE_NAMES, dev)))
            self.results.append(r)
            log(f"{self.name}: {name} trained and its C checked ({time.monotonic() - t:.1f} s, "
                f"{mlp.net.n_iter_} epochs)")

    def invert(self) -> None:
        t = time.monotonic()
        clean = gauss_newton(self.sensor, self.clean, GN_ITERS)
        noisy = gauss_newton(self.sensor, self.noisy, GN_ITERS)
        for k in GN_ITERS:
            r = Result(f"gauss-newton, {k} iteration{'s' if k > 1 else ''}", "inversion")
            r.clean = stats(clean[k] - self.poses)
            r.noisy = stats(noisy[k] - self.truth_noisy)
            r.evaluations = 11 * k
            self.results.append(r)
        log(f"{self.name}: Gauss-Newton inversion ({time.monotonic() - t:.1f} s)")

    def measure_costs(self, work: Path, jobs: int) -> None:
        def one(item):
            i, r = item
            folder = work / f"cost{i}"
            try:
                if r.model is not None:
                    inp = cost.write_inputs(self.clean, folder.with_suffix(".f64"))
                    binary = cost.build_bench(r.model, STYLE, "float", False, folder / "bench")
                    ins = cost.instruction_counts(binary, inp, folder / "bench", mix=False, repeat=False)["fn"]
                    sizes = cost.arm_sizes(r.model, STYLE, "float", False, folder / "m4f")
                    return r, ins, sizes["linked"], sizes["text"] + sizes["data"], ""
                if getattr(r, "mlp", None) is not None:
                    ins = r.mlp.instructions(self.clean, folder / "bench")
                    sizes = r.mlp.arm_sizes(folder / "m4f")
                    return r, ins, sizes["linked"], sizes["obj"], ""
                return r, None, None, None, ""
            except (InputError, RuntimeError, subprocess.SubprocessError) as exc:
                return r, None, None, None, str(exc).splitlines()[0][:200]

        work.mkdir(parents=True, exist_ok=True)
        with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
            for r, ins, flash, obj, err in pool.map(one, enumerate(self.results)):
                r.instructions, r.flash, r.obj = ins, flash, obj
                if err:
                    self.notes.append(f"{r.name}: cost not measured: {err}")

    def run(self, jobs: int) -> None:
        log(f"{self.name}: floor (Cramer-Rao bounds at {len(self.poses)} held-out poses)")
        self.floor()
        self.fit_linear()
        with tempfile.TemporaryDirectory(prefix="fitgen-estimators-") as tmp:
            self.fit_mlps(Path(tmp))
            self.invert()
            log(f"{self.name}: C builds, callgrind and Cortex-M4F links")
            self.measure_costs(Path(tmp) / "cost", jobs)
        log(f"{self.name}: done")


# --- report ---------------------------------------------------------------------------------------------

def terms_cell(r: Result) -> str:
    if r.family == "inversion":
        return "-"
    if r.family == "mlp":
        return f"{r.terms[0]} weights"
    return "/".join(map(str, r.terms)) + f" ({sum(r.terms)})"


def cost_cell(r: Result) -> str:
    if r.evaluations is not None:
        return f"{r.evaluations} field evals (not compiled)"
    return "-" if r.instructions is None else f"{r.instructions:.0f}"


def report(layouts: list[Layout]) -> None:
    print("# Estimators compared (bench/estimators.py)\n")
    print(f"Transfer {TRANSFER}. Training: the paper-sim grid (1,875 poses), noise-free. Held out: {N_HELD} random "
          f"poses in the paper-sim box (pose seed {POSE_SEED}); noisy: {NOISE_DRAWS} draws of the sensor's noise "
          f"(seeds 1..{NOISE_DRAWS}) pooled. Errors in mm (dx, dy, dz) and deg (thx, thy). Regression models: "
          "noise-free columns are Model.predict in double, noisy columns Model.predict(precision=\"float\") "
          "(the float C's arithmetic); MLPs: sklearn's predict noise-free, their float C on the noisy readings; "
          "Gauss-Newton: double Python. Instructions: per estimate inside tm_estimate (callgrind, x86-64, gcc "
          "-O2, float). Flash: what the estimator adds to a Cortex-M4F newlib program over an empty main "
          "(library code included); `.o`: the object's text + data.\n")

    print("## Summary\n")
    print("Worst RMS error with noise over the displacement outputs (mm) and over the tilt outputs (deg); "
          "in brackets, over the floor's RMS for the same output.\n")
    rows = []
    for L in layouts:
        for r in L.results:
            jd = int(np.argmax(r.noisy[1][:3]))
            jt = 3 + int(np.argmax(r.noisy[1][3:]))
            rows.append([L.name, r.name, terms_cell(r),
                         f"{fmt(r.worst_d)} ({fmt(r.worst_d / L.floor_rms[jd])}x)",
                         f"{fmt(r.worst_th)} ({fmt(r.worst_th / L.floor_rms[jt])}x)",
                         cost_cell(r), "-" if r.flash is None else str(r.flash)])
        rows.append([L.name, "floor (Cramer-Rao RMS)", "-", fmt(np.max(L.floor_rms[:3])),
                     fmt(np.max(L.floor_rms[3:])), "-", "-"])
    print(table(["layout", "method", "terms", "worst d RMS, noisy [mm]", "worst tilt RMS, noisy [deg]",
                 "instructions", "M4F flash [B]"], rows))
    print()

    for L in layouts:
        print(f"## {L.name} {TRANSFER}\n")
        print(f"Sensor `{L.name}`, noise {L.sensor.noise:g} {L.sensor.units} rms.\n")
        for note in L.notes:
            print(f"- {note}")
        for r in L.results:
            if r.note:
                print(f"- {r.name}: {r.note}")
        print()
        print("RMS / max error per output, noise-free and with noise; terms per output dx/dy/dz/thx/thy.\n")
        rows = []
        for r in L.results:
            rows.append([r.name, terms_cell(r)]
                        + [f"{fmt(r.clean[1][j])} / {fmt(r.clean[0][j])}" for j in range(5)]
                        + [f"{fmt(r.noisy[1][j])} / {fmt(r.noisy[0][j])}" for j in range(5)]
                        + [cost_cell(r), "-" if r.flash is None else str(r.flash),
                           "-" if r.obj is None else str(r.obj)])
        rows.append(["floor (Cramer-Rao RMS; median)", "-"] + ["-"] * 5
                    + [f"{fmt(L.floor_rms[j])} ({fmt(L.floor_median[j])})" for j in range(5)] + ["-", "-", "-"])
        print(table(["method", "terms"] + [f"{o} clean" for o in POSE_NAMES] + [f"{o} noisy" for o in POSE_NAMES]
                    + ["instructions", "M4F flash [B]", "M4F .o [B]"], rows))
        print()
        print("Regression models, where the noisy error comes from: the float arithmetic's largest deviation "
              "from double on the noise-free held-out readings, and the RMS error with noise in double.\n")
        rows = []
        for r in L.results:
            if r.model is None:
                continue
            rows.append([r.name] + [fmt(r.rounding[j]) for j in range(5)]
                        + [fmt(r.noisy_double[1][j]) for j in range(5)])
        print(table(["method"] + [f"{o} float - double" for o in POSE_NAMES]
                    + [f"{o} noisy RMS, double" for o in POSE_NAMES], rows))
        print()


def plot(layouts: list[Layout], folder: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fitgen.app.plots import _plain_log_ticks

    styles = {"ours": ("o", "C0", "ours (stepwise, AIC/BIC/caps)"),
              "harmonics": ("*", "C5", "ours, harmonics family (AIC/BIC/caps)"),
              "refine": ("P", "C6", "ours, harmonics + refinement steps"), "lasso": ("s", "C1", "LassoLarsIC (+ relaxed)"),
              "abess": ("D", "C2", "abess best subset"), "mlp": ("^", "C3", "MLP (float C)")}
    fig, axes = plt.subplots(2, len(layouts), figsize=(6.5 * len(layouts), 9), squeeze=False)
    for col, L in enumerate(layouts):
        for row, (attr, unit, sl) in enumerate((("worst_d", "mm", slice(0, 3)), ("worst_th", "deg", slice(3, 5)))):
            ax = axes[row][col]
            fl = float(np.max(L.floor_rms[sl]))
            pts = [(r, getattr(r, attr)) for r in L.results if r.family in styles and r.instructions is not None]
            sane = [y for r, y in pts if r.family != "abess"] + [fl]
            top = 3 * max(sane)
            seen = set()
            for r, y in pts:
                m, c, label = styles[r.family]
                off = y > top
                ax.scatter(r.instructions, min(y, top / 1.15), marker="^" if off else m, color=c, s=45, zorder=3,
                           label=None if r.family in seen else label, facecolors="none" if off else c)
                seen.add(r.family)
                tag = (r.name.split(" (")[0].replace("lasso-", "").replace("ours, ", "").replace("mlp ", "")
                       .replace("harmonics, ", "h ").replace("harmonics", "h"))
                if off:
                    tag += f" (off scale: {fmt(y)})"
                ax.annotate(tag, (r.instructions, min(y, top / 1.15)), fontsize=6.5, xytext=(4, -8 if off else 3),
                            textcoords="offset points", color=c)
            for r in L.results:
                if r.family == "inversion" and r.evaluations == max(GN_ITERS) * 11:
                    y = getattr(r, attr)
                    ax.axhline(y, color="C4", ls=":", lw=1.2)
                    ax.annotate(f"Gauss-Newton, {max(GN_ITERS)} iterations (not compiled): {fmt(y)}", (0.98, y),
                                xycoords=("axes fraction", "data"), fontsize=7, color="C4", ha="right",
                                xytext=(0, -9), textcoords="offset points")
            ax.axhline(fl, color="k", ls="--", lw=1)
            ax.annotate(f"Cramer-Rao floor (RMS over poses): {fmt(fl)}", (0.02, fl), xycoords=("axes fraction", "data"),
                        fontsize=7, xytext=(0, 3), textcoords="offset points")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_ylim(top=top)
            _plain_log_ticks(ax.yaxis, ax.get_ylim())  # 6, not 6 x 10^0; 1-2-3-5 over more than a decade
            # room on the right for the labels of the costliest points
            ax.set_xlim(right=4 * max(r.instructions for r, _ in pts))
            ax.set_xlabel("instructions per estimate (float C, x86-64, callgrind)")
            ax.set_ylabel(f"worst RMS error with noise [{unit}]")
            ax.set_title(f"{L.name} {TRANSFER}: worst of {'dx, dy, dz' if row == 0 else 'thx, thy'}")
            ax.grid(True, which="both", alpha=0.3)
    # one legend below the panels: in each, it covered the costliest points and their labels (MLP 64-64)
    handles = {label: h for ax in axes.flat for h, label in zip(*ax.get_legend_handles_labels())}
    fig.legend(list(handles.values()), list(handles), loc="lower center", ncol=3, fontsize=8)
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "estimators-front.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--plot", type=Path, metavar="DIR", help="write DIR/estimators-front.png")
    ap.add_argument("--jobs", type=int, default=2, help="parallel C builds and measurements (default 2)")
    ap.add_argument("--layouts", default=",".join(LAYOUTS), help=f"comma-separated (default {','.join(LAYOUTS)})")
    args = ap.parse_args(argv)
    layouts = []
    for name in args.layouts.split(","):
        L = Layout(name.strip())
        L.run(args.jobs)
        layouts.append(L)
    report(layouts)
    if args.plot:
        log(f"plot: {plot(layouts, args.plot)}")
    log(f"done: {len(layouts)} layouts in {time.monotonic() - START:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
