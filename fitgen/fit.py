"""Fitting the estimate equations: candidates, the stepwise search, the refit, two stages.

Stage 1 fits the displacement outputs; stage 2 the rotation outputs, whose d-terms use
the stage-1 estimates on the training rows (what the device will compute), or the true
displacements when asked.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from . import __version__
from .dataset import Dataset
from .errors import InputError
from .model import Equation, Model
from .pose import POSE_NAMES
from .stepwise import compress, refit, stepwise
from .terms import DISPLACEMENTS, EXPONENTS, ROTATIONS, candidate_terms, design_matrix, initial_terms


@dataclass(frozen=True)
class FitSettings:
    """Knobs of the search: penalty per term ``k`` (2: AIC, log(n): BIC), a cap on terms,
    the exponent family, whether rotations may use d-terms, and where those d's come from."""

    k: float | str = 2.0
    max_terms: int | None = None
    exponents: tuple[str, ...] = EXPONENTS
    d_terms: bool = True
    d_source: str = "estimated"  # or "true"

    def penalty(self, n: int) -> float:
        if self.k == "bic":
            return float(np.log(n))
        k = float(self.k)
        if not k > 0:
            raise InputError(f"the penalty per term must be > 0 (2 for AIC), got {self.k}")
        return k


def error_stats(err: np.ndarray) -> dict:
    """max |e|, RMS and 95th percentile of |e|."""
    a = np.abs(err)
    return {"max": float(a.max()), "rms": float(np.sqrt(np.mean(a * a))), "p95": float(np.percentile(a, 95))}


@dataclass
class FittedOutput:
    equation: Equation
    info: dict


def fit_output(name: str, inputs: np.ndarray, y: np.ndarray, d: np.ndarray | None, *,
               settings: FitSettings, positive: np.ndarray, progress=None) -> FittedOutput:
    """Choose and fit one output's equation."""
    n, n_in = inputs.shape
    cands = candidate_terms(n_in, name, exponents=settings.exponents,
                            d_terms=settings.d_terms and d is not None, positive=positive)
    init_terms = [t for t in initial_terms(n_in, settings.exponents) if t in set(cands)]
    init = [cands.index(t) for t in init_terms]
    if n < len(init) + 3:
        raise InputError(f"{n} rows cannot fit the {len(init) + 1} coefficients of the initial equation "
                         f"for {name} with residual degrees of freedom; give at least {len(init) + 3} rows")
    X = design_matrix(cands, inputs, d)
    if not np.all(np.isfinite(X)):
        raise InputError(f"a candidate term for {name} is not finite on the data (an input too close to 0?)")
    # keep at least one residual degree of freedom, so that RSS > 0 and AIC is finite
    cap = n - 2 if settings.max_terms is None else min(settings.max_terms, n - 2)
    if len(init) > cap:
        init = init[:cap]
    k = settings.penalty(n)
    A = compress(X, y)
    res = stepwise(X, y, init, names=[t.text for t in cands], k=k, max_terms=cap, compressed=A, progress=progress)
    terms = [cands[j] for j in res.selected]
    intercept, coefs, rss, cond = refit(A, res.selected)
    pred = intercept + X[:, res.selected] @ coefs
    info = {
        "terms": len(terms),
        "candidates": len(cands),
        "aic": res.aic,
        "rss": rss,
        "condition": cond,
        "aliased_skipped": [cands[j].text for j in res.aliased],
        "steps": [[s.move, s.aic] for s in res.trace],
        "training_error": error_stats(pred - y),
    }
    return FittedOutput(Equation(name, intercept, tuple(terms), tuple(float(c) for c in coefs)), info)


def fit_model(ds: Dataset, outputs: tuple[str, ...] | None = None, settings: FitSettings = FitSettings(),
              progress=None) -> Model:
    """Fit every requested output (default: all pose columns of the dataset), two stages."""
    outputs = tuple(ds.target_names) if outputs is None else tuple(outputs)
    if not outputs:
        raise InputError("nothing to fit: the dataset has no pose columns (dx,dy,dz,thx,thy)")
    for o in outputs:
        if o not in ds.target_names:
            raise InputError(f"cannot fit {o}: the dataset has no column {o}")
    if settings.d_source not in ("estimated", "true"):
        raise InputError(f"d_source must be 'estimated' or 'true', got {settings.d_source!r}")
    outputs = tuple(n for n in POSE_NAMES if n in outputs)
    v = ds.inputs
    lo, hi = v.min(axis=0), v.max(axis=0)
    positive = lo > 0

    fitted: dict[str, FittedOutput] = {}
    stage1 = [o for o in outputs if o in DISPLACEMENTS]
    for o in stage1:
        fitted[o] = fit_output(o, v, ds.target(o), None, settings=settings, positive=positive,
                               progress=progress and (lambda s, a, p, o=o: progress(o, s, a, p)))
    stage2 = [o for o in outputs if o in ROTATIONS]
    d = None
    if stage2 and settings.d_terms and all(x in stage1 for x in DISPLACEMENTS):
        if settings.d_source == "true":
            d = np.column_stack([ds.target(x) for x in DISPLACEMENTS])
        else:
            partial = Model(lo, hi, tuple(fitted[x].equation for x in DISPLACEMENTS))
            d = partial.predict(v)
    for o in stage2:
        fitted[o] = fit_output(o, v, ds.target(o), d, settings=settings, positive=positive,
                               progress=progress and (lambda s, a, p, o=o: progress(o, s, a, p)))

    info = {
        "generator": f"fitgen {__version__}",
        "method": "bidirectional stepwise regression on AIC (R step() rules), Householder QR refit",
        "settings": {**asdict(settings), "exponents": list(settings.exponents),
                     "k": settings.penalty(ds.n_rows)},
        "d_terms": "none" if d is None else settings.d_source,
        "dataset_sha256": ds.sha256,
        "dataset_rows": ds.n_rows,
        "sensor_sha256": ds.meta.get("sensor_sha256"),
        "outputs": {o: fitted[o].info for o in outputs},
    }
    units = ds.meta.get("units", "mT")
    model = Model(lo, hi, tuple(fitted[o].equation for o in outputs), units, info)
    # the errors of the model as the device computes it (rotations from estimated d's)
    pred = model.predict(v)
    for j, o in enumerate(outputs):
        info["outputs"][o]["model_training_error"] = error_stats(pred[:, j] - ds.target(o))
    return model
