"""Fitting the estimate equations: candidates, the stepwise search, the refit, two stages.

Stage 1 fits the displacement outputs; stage 2 the rotation outputs, whose d-terms use
the stage-1 estimates on the training rows (what the device will compute), or the true
displacements when asked.
"""

from __future__ import annotations

import itertools
from dataclasses import asdict, dataclass, replace

import numpy as np

from fitgen import __version__
from fitgen.fitting.augment import ROUNDING_FACTOR, UNIT_ROUNDOFF, gram_fold, noise_blocks, rounding_rows
from fitgen.physics.dataset import Dataset, refuse_huge
from fitgen.base.errors import InputError, is_finite_number, shown
from fitgen.equations.model import Equation, Model
from fitgen.physics.pose import POSE_NAMES
from fitgen.fitting.shared import SharedRows
from fitgen.fitting.stepwise import compress, refit, stepwise
from fitgen.equations.terms import (DISPLACEMENTS, EXPONENTS, FAMILIES, HARMONIC_DEGREE, ROTATIONS, Harmonics, candidate_terms,
                    design_jacobian, finite_design_matrix, initial_terms)


@dataclass(frozen=True)
class FitSettings:
    """Knobs of the search: penalty per term ``k`` (2: AIC, log(n): BIC), a cap on terms,
    the exponent family, the degree of the ring's harmonic monomials (0: none), whether rotations
    may use d-terms, where those d's come from, what the device adds: its reading noise and
    its precision (fitgen.fitting.augment), and the refinement steps after the equations (fitgen.equations.refine)."""

    k: float | str = 2.0
    max_terms: int | None = None
    exponents: tuple[str, ...] = EXPONENTS
    d_terms: bool = True
    d_source: str = "estimated"  # or "true"
    # the reading noise (rms, input units) the device will see; None: the sensor named in the
    # dataset's meta, or what measured data carry. 0 with precision None: the data as given (R's step()).
    noise: float | None = None
    # the precision the equations must survive (fitgen.fitting.augment.UNIT_ROUNDOFF); None: exact arithmetic
    precision: str | None = "float"
    # its rounding taken as noise of this many unit roundoffs per term (fitgen.fitting.family raises it where the
    # device's rounding would matter on validation poses)
    rounding_factor: float = ROUNDING_FACTOR
    harmonic_degree: int = 0
    # Gauss-Newton steps on a fitted forward model after the equations (fitgen.equations.refine; 0: none), and
    # the cap on that model's terms per element
    refine: int = 0
    refine_terms: int = 30

    @classmethod
    def family(cls, name: str, **kw) -> "FitSettings":
        """Settings with a named candidate family (fitgen.equations.terms.FAMILIES)."""
        return cls(**kw).with_family(name)

    def with_family(self, name: str) -> "FitSettings":
        """These settings with the candidates of family ``name`` instead."""
        if name not in FAMILIES:
            raise InputError(f"unknown family {name!r} (families: {', '.join(FAMILIES)})")
        return replace(self, exponents=FAMILIES[name], harmonic_degree=HARMONIC_DEGREE.get(name, 0))

    @classmethod
    def exact(cls, **kw) -> "FitSettings":
        """The paper's procedure: the data as given, exact arithmetic (what R's step() computes)."""
        return cls(noise=0.0, precision=None, **kw)

    def __post_init__(self):
        for name, value in vars(self).items():  # numpy's numbers as Python's: the model file's JSON takes those only
            if isinstance(value, np.generic):
                object.__setattr__(self, name, value.item())
        # set in a notebook: said here, not as a float() of 'aic' or an argmin of nothing inside the search
        if not (self.k in ("aic", "bic") or (is_finite_number(self.k) and self.k > 0)):
            raise InputError("k, the penalty per term, is 'aic', 'bic' or a number > 0 (2 for AIC), "
                             f"got {shown(self.k)}")
        if self.max_terms is not None and not (isinstance(self.max_terms, (int, np.integer))
                                               and not isinstance(self.max_terms, bool) and self.max_terms >= 1):
            raise InputError(f"max_terms is None or a whole number >= 1, got {shown(self.max_terms)}")

    def penalty(self, n: int) -> float:
        if self.k == "bic":
            return float(np.log(n))
        return 2.0 if self.k == "aic" else float(self.k)


def error_stats(err: np.ndarray) -> dict:
    """max |e|, RMS and 95th percentile of |e|."""
    a = np.abs(err)
    return {"max": float(a.max()), "rms": float(np.sqrt(np.mean(a * a))), "p95": float(np.percentile(a, 95))}


@dataclass
class FittedOutput:
    equation: Equation
    info: dict


ROWS = 1 << 14  # rows per block: the candidate columns are never all in memory at once


def rows_needed(n_inputs: int, settings: FitSettings | None = None) -> int:
    """The rows :func:`fit_output` asks for at least: the initial equation's coefficients and residual degrees of
    freedom."""
    return len(initial_terms(n_inputs, (settings or FitSettings()).exponents)) + 3


def fit_output(name: str, inputs: np.ndarray, y: np.ndarray, d: np.ndarray | None, *,
               settings: FitSettings, positive: np.ndarray, progress=None, noise: float = 0.0,
               d_jac=None, harmonics: Harmonics | None = None, shared: SharedRows | None = None) -> FittedOutput:
    """Choose and fit one output's equation. The search's memory grows with the candidates, not with the rows;
    the training error at the end holds a few numbers per row (its 95th percentile needs them all), which sets
    the peak past about a million rows (docs/fit-benchmark.md, part 3).

    ``noise``: reading noise (rms) to add in expectation (fitgen.fitting.augment); ``d_jac``: a function
    (lo, hi) -> the gradient of the displacement estimates ``d`` by the inputs on those rows, for
    the d-terms' share of it; ``shared``: the compressed rows shared with other fits (fitgen.fitting.shared).
    """
    n, n_in = inputs.shape
    cands = candidate_terms(n_in, name, exponents=settings.exponents,
                            d_terms=settings.d_terms and d is not None, positive=positive,
                            harmonics=harmonics, harmonic_degree=settings.harmonic_degree)
    init_terms = [t for t in initial_terms(n_in, settings.exponents) if t in set(cands)]
    init = [cands.index(t) for t in init_terms]
    if n < len(init) + 3:
        raise InputError(f"{n} rows cannot fit the {len(init) + 1} coefficients of the initial equation for {name} "
                         "and leave the two residual degrees of freedom the search starts with"
                         + (" (--max-terms cuts it down by its fit)" if settings.max_terms is not None else "")
                         + f"; give at least {len(init) + 3} rows")

    def columns(lo, hi, terms=cands):
        return finite_design_matrix(terms, inputs[lo:hi], None if d is None else d[lo:hi], harmonics, lo,
                                    f" for {name}")

    # keep at least one residual degree of freedom, so that RSS > 0 and AIC is finite
    cap = n - 2 if settings.max_terms is None else min(settings.max_terms, n - 2)
    k = settings.penalty(n)
    if shared is not None and not shared.serves(inputs, noise, harmonics):
        shared = None
    A = None if shared is None else shared.triangle(cands, y, d)
    if A is None:
        A = compress(columns, y, block=ROWS)
    extra = []
    if settings.precision is not None:
        # from the data's own triangle, before the noise rows: rounding scales with the terms' sizes
        extra.append([rounding_rows(A, settings.rounding_factor * UNIT_ROUNDOFF[settings.precision])])
    gram = None
    if noise > 0 and gram_fold(settings.precision):
        gram = (shared or SharedRows(inputs, noise, harmonics)).gram(cands, d, d_jac)
    elif noise > 0:
        extra.append(noise_blocks(cands, inputs, noise, d, d_jac, rows=ROWS // 8, harmonics=harmonics))
    if extra or gram is not None:
        A = compress(None, y[:0], extra=itertools.chain(*extra), start=A, gram=gram)
    init, capped = within_cap(A, init, cap)
    # exchanges at a cap the user set; at n - 2 alone the search stays R's, which has none
    res = stepwise(None, y, init, names=[t.text for t in cands], k=k, max_terms=cap, compressed=A, progress=progress,
                   exchange=settings.max_terms is not None)
    terms = [cands[j] for j in res.selected]
    intercept, coefs, rss, cond = refit(A, res.selected)
    pred = np.concatenate([intercept + columns(lo, min(n, lo + ROWS), terms) @ coefs for lo in range(0, n, ROWS)])
    info = {
        "terms": len(terms),
        "candidates": len(cands),
        "aic": res.aic,
        "rss": rss,
        "condition": cond,
        "aliased_skipped": [cands[j].text for j in res.aliased],
        "initial_over_cap": [cands[j].text for j in capped],  # dropped from eq. 1 to start within the cap
        "steps": [[s.move, s.aic] for s in res.trace],
        "training_error": error_stats(pred - y),
    }
    return FittedOutput(Equation(name, intercept, tuple(terms), tuple(float(c) for c in coefs)), info)


def within_cap(A: np.ndarray, init: list[int], cap: int) -> tuple[list[int], list[int]]:
    """The initial equation reduced to ``cap`` terms, and the terms dropped in order: one at a time, the term
    whose removal raises the RSS least (backward elimination on the compressed rows ``A``), so that a cap below
    eq. 1's size starts the search from eq. 1's best terms, not from its first elements."""
    init, dropped = list(init), []
    while len(init) > cap:
        rss = [refit(A, [j for j in init if j != drop])[2] for drop in init]
        dropped.append(init.pop(int(np.argmin(rss))))
    return init, dropped


def noise_to_add(ds: Dataset, settings: FitSettings, sensor=None) -> dict:
    """The reading noise the fit adds in expectation, and where the figures come from.

    device: ``settings.noise``, else the single-sample noise a capture measured (the unit's own), else
    the noise figure of ``sensor`` or of the sensor named in a simulated dataset's meta. data: the noise a
    simulated dataset was made with; for a capture (``samples_per_row`` in its meta), the noise its
    averaged rows carry: what it measured per row, else the device's over sqrt(samples). Measured
    rows with no such record are taken as single samples that carry the device's own noise.
    Added: sqrt(device^2 - data^2), 0 when the data are already as noisy (never counted twice).
    """
    from fitgen.physics.simulate import dataset_sensor

    if settings.noise is not None and not settings.noise >= 0:
        raise InputError(f"noise must be >= 0, got {settings.noise}")
    meta = ds.meta
    data = _number(meta.get("noise"))
    if settings.noise is not None:
        device, source = float(settings.noise) + 0.0, "given"  # + 0.0: -0 is 0
    else:
        sensor = sensor or dataset_sensor(meta)
        measured = _rms(meta.get("sample_noise"))
        if measured:  # the unit's own noise: a drawing's figure is another sensor's
            device, source = measured, "measured by the capture (single samples)"
        elif sensor is not None:
            device, source = sensor.noise, f"sensor {sensor.name}"
        else:
            device, source = None, "unknown"
    samples = meta.get("samples_per_row")
    data_source = "simulated" if data is not None else None
    if data is None and isinstance(samples, int) and samples >= 1:
        data, data_source = _rms(meta.get("row_noise")), f"measured by the capture ({samples} samples per row)"
        if data is None and device is not None:
            data, data_source = device / np.sqrt(samples), f"the device's over sqrt({samples} samples per row)"
    if device is None:
        added, why = 0.0, "no device noise known"
    elif data is None:
        added, why = 0.0, ("measured rows with no samples_per_row in their meta: taken as single samples, which "
                           "carry the device's noise")
    else:
        try:
            added = float(np.sqrt(max(device**2 - data**2, 0.0)))
        except OverflowError:  # a figure near 1e300: a typo, not a sensor's noise
            raise InputError(f"a noise figure of {max(device, data):g} is no sensor's (--noise, or the meta's)") \
                from None
        why = "the device's single-sample noise less the rows' own"
    return {"device": device, "device_source": source, "data": data, "data_source": data_source, "added": added,
            "why": why}


def _number(x) -> float | None:
    return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x) else None


def _rms(values) -> float | None:
    """The rms of a per-element list of noise figures (None when there is none)."""
    if not isinstance(values, list) or not values or not all(_number(v) is not None and v >= 0 for v in values):
        return None
    return float(np.sqrt(np.mean(np.square(values))))


def _d_jacobian(equations, v: np.ndarray, harmonics=None):
    """A function (lo, hi) -> the (hi - lo, 3, N) gradient of the displacement equations by the inputs;
    its ``equations``: those equations (fitgen.fitting.augment forms the gradient from their terms' own rows)."""
    def block(lo, hi):
        out = np.zeros((hi - lo, 3, v.shape[1]))
        for eq in equations:
            out[:, DISPLACEMENTS.index(eq.name), :] = design_jacobian(
                list(eq.terms), v[lo:hi], harmonics=harmonics) @ np.asarray(eq.coefficients)
        return out
    block.equations = equations
    return block


def ring_harmonics(ds: Dataset, sensor=None) -> Harmonics:
    """The harmonics of the dataset's sensor's ring: from each element's azimuth about the board's z axis."""
    from fitgen.physics.simulate import dataset_sensor

    sensor = sensor or dataset_sensor(ds.meta)
    if sensor is None:
        raise InputError("the harmonics family needs the elements' positions: give --sensor (a preset or a TOML file)")
    if sensor.n_elements != ds.n_inputs:
        raise InputError(f"sensor {sensor.name} has {sensor.n_elements} elements; the data have {ds.n_inputs} inputs")
    x, y = sensor.positions[:, 0], sensor.positions[:, 1]
    # an element on the axis has no azimuth (arctan2(0, 0) is 0, as if it sat at +x): it weighs in no harmonic
    return Harmonics.from_azimuths(np.where(np.hypot(x, y) < 1e-9, np.nan, np.arctan2(y, x)))


def fit_model(ds: Dataset, outputs: tuple[str, ...] | None = None, settings: FitSettings = FitSettings(),
              progress=None, sensor=None, forward=None, shared: SharedRows | None = None) -> Model:
    """Fit every requested output (default: all pose columns of the dataset), two stages.

    ``sensor``: the device's sensor when the dataset's meta does not name it (for its noise figure);
    ``forward``: with ``settings.refine``, a forward model already fitted to ``ds`` (refine_fit.fit_forward);
    ``shared``: the compressed rows of ``ds`` to share with other fits of it (fitgen.fitting.family).
    """
    outputs = tuple(ds.target_names) if outputs is None else tuple(outputs)
    if not outputs:
        raise InputError("nothing to fit: the dataset has no pose columns (dx,dy,dz,thx,thy)")
    for o in outputs:
        if o not in ds.target_names:
            raise InputError(f"cannot fit {o}: the dataset has no column {o}")
    if settings.d_source not in ("estimated", "true"):
        raise InputError(f"d_source must be 'estimated' or 'true', got {shown(settings.d_source)}")
    outputs = tuple(n for n in POSE_NAMES if n in outputs)
    refuse_huge(ds)  # its powers overflow: said where it is, not as a candidate term that is not finite
    if settings.refine:
        from fitgen.fitting.refine_fit import check_refinable

        check_refinable(ds, outputs, settings.refine, settings.refine_terms)  # before the equations' fit
    if settings.precision is not None and settings.precision not in UNIT_ROUNDOFF:
        raise InputError(f"precision must be one of {', '.join(UNIT_ROUNDOFF)} or None, "
                         f"got {shown(settings.precision)}")
    noise = noise_to_add(ds, settings, sensor)
    v = ds.inputs
    if len(v) < 2:  # a Dataset made by hand, or a scene's rows all but one lifted: not numpy's, not a dead element
        raise InputError(f"the dataset has {'one row' if len(v) else 'no rows'}: too few to fit")
    lo, hi = v.min(axis=0), v.max(axis=0)
    if len(flat := np.flatnonzero(lo == hi)):  # a domain of no width, which every model file reader refuses
        raise InputError(f"{', '.join(f'v{k + 1}' for k in flat)} read{'s' if len(flat) == 1 else ''} one value on "
                         f"every row (v{flat[0] + 1}: {float(lo[flat[0]]):g}): a dead element, a broken wire, an empty "
                         "ADC channel, or an element saturated throughout carries nothing a model can use, nor can "
                         "predict, codegen or the device take its one-value range: mend it and capture again, or, on a "
                         "sensor file of your own, leave the element out")
    positive = lo > 0
    harmonics = ring_harmonics(ds, sensor) if settings.harmonic_degree > 0 else None
    if harmonics is not None and not np.sum(lo) > 0:
        raise InputError("the harmonics family divides by the readings' sum, which is not > 0 over the data's "
                         f"domain (lowest {float(np.sum(lo)):.4g}): fit another family")
    y = ds.targets[:, [ds.target_names.index(o) for o in outputs]]
    still = [o for o, col in zip(outputs, y.T) if np.ptp(col) == 0]
    if still:
        varying = ",".join(o for o in outputs if o not in still) or ",".join(
            o for o, col in zip(ds.target_names, ds.targets.T) if np.ptp(col) > 0)  # the data's, where none asked for
        raise InputError(f"{still[0]} is {y[0, outputs.index(still[0])]:g} in every row: nothing to fit"
                         + (f" (fit the outputs that vary: --outputs {varying})" if varying else ""))

    fitted: dict[str, FittedOutput] = {}
    if shared is None or not shared.serves(v, noise["added"], harmonics):
        shared = SharedRows(v, noise["added"], harmonics)  # the outputs share their noise rows
    stage1 = [o for o in outputs if o in DISPLACEMENTS]
    for o in stage1:
        fitted[o] = fit_output(o, v, ds.target(o), None, settings=settings, positive=positive,
                               progress=progress and (lambda s, a, p, o=o: progress(o, s, a, p)),
                               noise=noise["added"], harmonics=harmonics, shared=shared)
    stage2 = [o for o in outputs if o in ROTATIONS]
    d = d_jac = None
    if stage2 and settings.d_terms and all(x in stage1 for x in DISPLACEMENTS):
        stage1_eqs = tuple(fitted[x].equation for x in DISPLACEMENTS)
        if settings.d_source == "true":
            d = np.column_stack([ds.target(x) for x in DISPLACEMENTS])
        else:
            d = Model(lo, hi, stage1_eqs, harmonics=harmonics).predict(v)
        if noise["added"] > 0:
            # the device computes d from the same noisy readings, whatever d trained on
            d_jac = _d_jacobian(stage1_eqs, v, harmonics)
    for o in stage2:
        fitted[o] = fit_output(o, v, ds.target(o), d, settings=settings, positive=positive,
                               progress=progress and (lambda s, a, p, o=o: progress(o, s, a, p)),
                               noise=noise["added"], d_jac=d_jac, harmonics=harmonics, shared=shared)

    info = {
        "generator": f"fitgen {__version__}",
        "method": "bidirectional stepwise regression on AIC (R step() rules), Householder QR refit",
        "settings": {**asdict(settings), "exponents": list(settings.exponents),
                     "k": settings.penalty(ds.n_rows)},
        "noise": noise,
        "precision": {"target": settings.precision,
                      "rounding_noise": None if settings.precision is None
                      else settings.rounding_factor * UNIT_ROUNDOFF[settings.precision]},
        "d_terms": "none" if d is None else settings.d_source,
        "dataset_sha256": ds.sha256,
        "dataset_rows": ds.n_rows,
        "sensor_sha256": ds.meta.get("sensor_sha256"),
        "outputs": {o: fitted[o].info for o in outputs},
    }
    units = ds.meta.get("units") or (sensor.units if sensor is not None else "mT")  # a dataset made in numpy
    model = Model(lo, hi, tuple(fitted[o].equation for o in outputs), units, info, harmonics)
    if settings.refine:
        from fitgen.fitting.refine_fit import fit_refinement

        model.refine, info["refine"] = fit_refinement(ds, model, steps=settings.refine, noise=noise["added"],
                                                      max_terms=settings.refine_terms, progress=progress,
                                                      forward=forward)
    # the errors of the model as the device computes it (rotations from estimated d's)
    pred = model.predict(v)
    alone = None if model.refine is None else replace(model, refine=None).predict(v)  # what the steps change
    for j, o in enumerate(outputs):
        info["outputs"][o]["model_training_error"] = error_stats(pred[:, j] - ds.target(o))
        if alone is not None:
            info["outputs"][o]["equations_training_error"] = error_stats(alone[:, j] - ds.target(o))
    return model
