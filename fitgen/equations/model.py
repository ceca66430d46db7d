"""The fitted model: a small typed object that the Python evaluator and the C templates both read.

Model files are JSON (``schema_version`` 1): the input domain (and, for harmonic terms, the
ring's harmonic weights), per output its terms (canonical text), coefficients and intercept,
and how and on what it was fitted.
"""

from __future__ import annotations

import copy
import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fitgen import __version__
from fitgen.base.errors import InputError, finite_number, is_finite_number, of_kind, required, shown
from fitgen.base.fileio import read_text, real_file, write_atomic
from fitgen.base.texts import canonical_json, sha256_hex, text_kind
from fitgen.equations.floatrange import float_domain, float_problem
from fitgen.equations.fma import fma as fused_multiply_add
from fitgen.physics.dataset import READING_UNITS
from fitgen.physics.pose import POSE_NAMES, POSE_UNITS
from fitgen.physics.relocate import relocated
from fitgen.equations.refine import Refinement
from fitgen.equations.terms import DISPLACEMENTS, Harmonics, Term, design_matrix, monomial_factors, parse_term

SCHEMA_VERSION = 1
BOX_LIMIT = 1e4  # a held-out box's bounds, mm or deg
STATUS_NONFINITE = -1
MAX_INPUTS = 30  # the C status is a positive int with one bit per input (the headers assert it)
_ROWS = 1 << 15  # rows per block of predict


@dataclass(frozen=True)
class Equation:
    """One output: ``intercept + sum(coefficients[j] * terms[j])``."""

    name: str
    intercept: float
    terms: tuple[Term, ...]
    coefficients: tuple[float, ...]

    @property
    def unit(self) -> str:
        return POSE_UNITS[POSE_NAMES.index(self.name)]

    @property
    def uses_d(self) -> bool:
        return any(t.mult for t in self.terms)


@dataclass
class Model:
    """Equations in output order (displacements before rotations) and the fitted input domain."""

    input_min: np.ndarray
    input_max: np.ndarray
    equations: tuple[Equation, ...]
    input_units: str = "mT"
    fit_info: dict = field(default_factory=dict)
    harmonics: Harmonics | None = None  # the ring's, when a term uses them
    refine: Refinement | None = None  # Gauss-Newton steps on a forward model after the equations (fitgen.equations.refine)

    def __post_init__(self):
        self.input_min = np.asarray(self.input_min, dtype=float)
        self.input_max = np.asarray(self.input_max, dtype=float)
        _validate(self, "model")

    @property
    def n_inputs(self) -> int:
        return int(self.input_min.size)

    @property
    def output_names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.equations)

    @property
    def held_out_box(self) -> dict[str, tuple[float, float]]:
        """The pose box the model was fitted and held out in, per output its record names (its ``held_out``
        record's ``box``); empty without one."""
        box = (self.fit_info.get("held_out") or {}).get("box") or {}
        return {o: (float(box[o][0]), float(box[o][1])) for o in self.output_names if o in box}

    @property
    def pose_box(self) -> dict[str, tuple[float, float]]:
        """The pose box the model was fitted and held out in, over every pose component its ``held_out`` record's
        ``box`` names (a scene's held components too, which :attr:`held_out_box` leaves out); empty without one."""
        box = (self.fit_info.get("held_out") or {}).get("box") or {}
        return {o: (float(box[o][0]), float(box[o][1])) for o in POSE_NAMES if o in box}

    def far_bounds(self) -> tuple[list[int], np.ndarray, np.ndarray]:
        """(output columns, low, high): an estimate below low or above high lies outside :attr:`held_out_box` by
        more than the box's width, as readings of another sensor do (the drawing's model on a built unit's). No
        columns without a box."""
        box = self.held_out_box
        cols = [j for j, o in enumerate(self.output_names) if o in box]
        lo = np.array([box[self.output_names[j]][0] for j in cols])
        hi = np.array([box[self.output_names[j]][1] for j in cols])
        return cols, lo - (hi - lo), hi + (hi - lo)

    def far_per_output(self) -> tuple:
        """:meth:`far_bounds` per output in order: (low, high), or None for an output the box does not name."""
        cols, lo, hi = self.far_bounds()
        by = {j: (float(a), float(b)) for j, a, b in zip(cols, lo, hi)}
        return tuple(by.get(j) for j in range(len(self.equations)))

    def far_outside(self, pred: np.ndarray) -> np.ndarray:
        """Per row of estimates ``pred`` (rows x outputs), whether one lies beyond :meth:`far_bounds`; a
        non-finite estimate is not counted."""
        pred = np.atleast_2d(np.asarray(pred, dtype=float))
        cols, lo, hi = self.far_bounds()
        with np.errstate(invalid="ignore"):
            return np.any((pred[:, cols] < lo) | (pred[:, cols] > hi), axis=1)

    @property
    def held_out_rest(self) -> np.ndarray | None:
        """The readings the model's sensor gives at rest, noise-free (its ``held_out`` record's ``rest``, one per
        input); None without one."""
        rest = (self.fit_info.get("held_out") or {}).get("rest")
        if not isinstance(rest, list) or len(rest) != self.n_inputs:
            return None
        out = np.array(rest, dtype=float)
        return out if np.all(np.isfinite(out)) else None

    @property
    def held_out_rest_spread(self) -> np.ndarray | None:
        """How far the rest readings of units built within the tolerances of its unit's drawing spread (a standard
        deviation per input; its ``held_out`` record's ``rest_spread``, a twin's); None without one."""
        spread = (self.fit_info.get("held_out") or {}).get("rest_spread")
        if not isinstance(spread, list) or len(spread) != self.n_inputs:
            return None
        return np.array(spread, dtype=float)

    def equation(self, name: str) -> Equation:
        for e in self.equations:
            if e.name == name:
                return e
        raise InputError(f"the model has no output {name!r} (it has {', '.join(self.output_names)})")

    # --- evaluation ------------------------------------------------------------

    def clamp(self, inputs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Inputs clamped into the domain, and the status per row (C's return value).

        Status: 0 inside, bit k-1 set when input k was clamped, -1 for a non-finite input.
        """
        v = np.asarray(inputs, dtype=float)
        if v.ndim == 1:
            v = v[None, :]
        if v.ndim != 2:
            raise InputError(f"the model takes rows of {self.n_inputs} inputs (a 1-D or 2-D array), got shape "
                             f"{v.shape}")
        if v.shape[1] != self.n_inputs:
            raise InputError(f"the model takes {self.n_inputs} inputs, got {v.shape[1]}")
        finite = np.all(np.isfinite(v), axis=1)
        low, high = v < self.input_min, v > self.input_max
        bits = (1 << np.arange(self.n_inputs)).astype(np.int64)
        status = ((low | high) * bits).sum(axis=1)
        status[~finite] = STATUS_NONFINITE
        clamped = np.clip(np.where(np.isfinite(v), v, self.input_min), self.input_min, self.input_max)
        return clamped, status

    def float_problem(self) -> str:
        """Why the model cannot run in float ('' when it can): fitgen.equations.floatrange.float_problem."""
        return float_problem(self)

    def predict(self, inputs: np.ndarray, with_status: bool = False, fma: bool = False,
                precision: str = "double"):
        """Outputs (n, n_outputs) for rows of inputs; rows with a non-finite input give 0.

        ``fma``: each term added with one rounding, as C generated with fused multiply-adds does.
        ``precision="float"``: the float C's arithmetic in numpy float32 (inputs, domain,
        coefficients, powers and sums rounded as the float header rounds them; no fma).
        A refinement (fitgen.equations.refine) runs after the equations, without fma in either precision.
        Rows are taken in blocks, so that memory does not grow with their number.
        """
        rows = np.asarray(inputs, dtype=float)
        if rows.ndim == 2 and rows.shape[0] > _ROWS:
            parts = [self.predict(rows[lo:lo + _ROWS], True, fma, precision) for lo in range(0, rows.shape[0], _ROWS)]
            out, status = np.vstack([p[0] for p in parts]), np.concatenate([p[1] for p in parts])
            return (out, status) if with_status else out
        if precision == "float":
            if fma:
                raise InputError("the float emulation has no fused multiply-add")
            problem = self.float_problem()
            if problem:
                raise InputError(problem)
            lo, hi = float_domain(self)
            f32 = np.asarray(inputs, dtype=float).astype(np.float32).astype(float)
            v, status = dataclasses.replace(self, input_min=lo, input_max=hi, fit_info={}).clamp(f32)
            dtype = np.float32
        elif precision == "double":
            v, status = self.clamp(inputs)
            dtype = np.float64
        else:
            raise InputError(f"predict evaluates in double or float, not {precision!r}")
        v = v.astype(dtype)
        out = np.zeros((v.shape[0], len(self.equations)))
        d = np.zeros((v.shape[0], 3), dtype=dtype)
        for j, eq in enumerate(self.equations):
            cols = design_matrix(list(eq.terms), v, d, self.harmonics).astype(dtype, copy=False)
            # summed term by term in model order, as the generated C does, so that both round alike
            acc = np.full(v.shape[0], eq.intercept, dtype=dtype)
            for c, col in zip(np.asarray(eq.coefficients, dtype=dtype), cols.T):
                acc = fused_multiply_add(c, col, acc) if fma else acc + c * col
            out[:, j] = acc
            if eq.name in DISPLACEMENTS:
                d[:, DISPLACEMENTS.index(eq.name)] = acc
        if self.refine is not None:
            out = self.refine.apply(v, out.astype(dtype), dtype).astype(float)
        out[status < 0] = 0.0
        return (out, status) if with_status else out

    # --- files -------------------------------------------------------------------

    def with_domain(self, lo, hi) -> "Model":
        """The same equations (and harmonics) on another input domain, without the fit notes."""
        return dataclasses.replace(self, input_min=np.asarray(lo, dtype=float), input_max=np.asarray(hi, dtype=float),
                                   fit_info={})

    def to_dict(self) -> dict:
        return self._as_dict(copy.deepcopy(self.fit_info))  # a caller that edits the dict leaves the model as it was

    def _as_dict(self, fit) -> dict:
        inputs = {
            "names": [f"v{k}" for k in range(1, self.n_inputs + 1)],
            "units": self.input_units,
            "min": self.input_min.tolist(),
            "max": self.input_max.tolist(),
        }
        if self.harmonics is not None:
            inputs["harmonics"] = self.harmonics.to_dict()
        out = {
            "schema_version": SCHEMA_VERSION,
            "generator": f"fitgen {__version__}",
            "inputs": inputs,
            "outputs": [
                {"name": e.name, "unit": e.unit, "intercept": e.intercept,
                 "terms": [t.text for t in e.terms], "coefficients": list(e.coefficients)}
                for e in self.equations
            ],
            "fit": fit,
        }
        if self.refine is not None:
            out["refine"] = self.refine.to_dict()
        return out

    @property
    def sha256(self) -> str:
        """Hash of what the estimate depends on (domain, equations, refinement), not of the fit notes."""
        d = self._as_dict(None)
        return sha256_hex(canonical_json({k: d[k] for k in ("inputs", "outputs", "refine") if k in d}))

    def save(self, path: str | Path) -> Path:
        try:
            text = json.dumps(self.to_dict(), indent=1, allow_nan=False) + "\n"
        except ValueError:
            raise InputError("the model holds a non-finite number; not written") from None
        return write_atomic(path, text)


# where readings in these units come from, for the hint of check_input_units
_UNITS_SOURCE = {"V": " (fitgen simulate --transfer gmr, or tactile-host capture)",
                 "mT": " (fitgen simulate --transfer raw)"}


def check_input_units(model: Model, units: str | None, readings: str, origin: str = "the model") -> None:
    """InputError (one line) when readings in ``units`` are not in the units ``model`` takes.

    ``units`` None (not recorded: a CSV without a meta file) passes. ``readings`` and ``origin`` name
    the readings and the model in the message (e.g. "the ADCs' readings", "model m.json").
    """
    if units is None or units == model.input_units:
        return
    other = "" if "ADC" in readings else f", or give readings in {model.input_units}"  # a device's are what they are
    raise InputError(f"{origin} takes inputs in {model.input_units}; {readings} are in {units}: fit it on a dataset "
                     f"in {units}{_UNITS_SOURCE.get(units, '')}{other}")


INPUT_UNITS = READING_UNITS


def load_model(path: str | Path) -> Model:
    origin = f"model file {path}"
    text = read_text(path, "model file")
    try:
        data = json.loads(text)
    except ValueError as exc:
        # a dataset or a sensor file given for the model: named as such
        seen = {"toml": "TOML (a sensor file?)", "csv": "CSV (a dataset?)"}.get(text_kind(text))
        raise InputError(f"{origin}: " + (f"{seen}, not a model (JSON, as fitgen fit writes it)" if seen else
                                          f"not valid JSON: {exc}")) from None
    model = model_from_dict(data, origin)
    held = model.fit_info.get("held_out")
    if isinstance(held, dict):  # a folder moved with the unit's file its figures were held out on: found beside it
        model.fit_info["held_out"] = relocated(held, real_file(path).parent)
    return model


def model_from_dict(data, origin: str = "model") -> Model:
    if not isinstance(data, dict):
        raise InputError(f"{origin}: not a model (a JSON object is expected)")
    ver = data.get("schema_version")
    if ver is None and "outputs" not in data:  # another JSON file: a dataset's meta, a blob, a report
        what = "a dataset's meta file" if "columns" in data else "JSON without a model's schema_version and outputs"
        raise InputError(f"{origin}: not a model but {what}; `fitgen fit DATA.csv -o MODEL.json` writes a model")
    if type(ver) is not int or ver != SCHEMA_VERSION:  # true and 1.0 compare equal to 1
        raise InputError(f"{origin}: schema_version {ver!r} is not supported (this fitgen reads {SCHEMA_VERSION})")
    try:
        fix = " (fit the model again, or restore the file)"
        inputs = required(data, "inputs", f"{origin}: inputs", dict, fix)
        lo, hi = ([finite_number(x, f"{origin}: inputs.{k}") for x in required(inputs, k, f"{origin}: inputs.{k}",
                                                                                list, fix)] for k in ("min", "max"))
        units = inputs.get("units", "mT")
        harmonics = Harmonics.from_dict(inputs["harmonics"], len(lo), origin) if "harmonics" in inputs else None
        eqs = []
        for i, o in enumerate(required(data, "outputs", f"{origin}: outputs", list, fix)):
            where = f"{origin}: outputs[{i}]"
            for key, kind in (("name", object), ("intercept", object), ("terms", list), ("coefficients", list)):
                required(of_kind(o, dict, where, fix), key, f"{where}.{key}", kind, fix)
            terms = tuple(_term(t, where) for t in o["terms"])
            coefs = tuple(finite_number(c, f"{where}.coefficients") for c in o["coefficients"])
            if len(terms) != len(coefs):
                raise InputError(f"{where}: {len(terms)} terms but {len(coefs)} coefficients")
            own = POSE_UNITS[POSE_NAMES.index(o["name"])] if o["name"] in POSE_NAMES else None
            if own is not None and o.get("unit", own) != own:  # the estimate is in its own, whatever the file says
                raise InputError(f"{where}.unit: {o['name']} is estimated in {own}, not {o['unit']!r:.40} (the "
                                 "coefficients are fitted in it; an edit does not convert them)")
            eqs.append(Equation(o["name"], finite_number(o["intercept"], f"{where}.intercept"), terms, coefs))
    except (KeyError, TypeError) as exc:
        raise InputError(f"{origin}: malformed model ({type(exc).__name__}: {exc})") from None
    if units not in INPUT_UNITS:
        raise InputError(f"{origin}: inputs.units must be {' or '.join(INPUT_UNITS)}, got {shown(units)}")
    if len(hi) != len(lo):  # said before the names, which are checked against min's length
        raise InputError(f"{origin}: inputs.min has {len(lo)} values and inputs.max {len(hi)}: one per input")
    k = next((k for k, (a, b) in enumerate(zip(lo, hi)) if a == b), None)
    if k is not None:  # clamped there, every estimate is one far point (predict read -564 mm at every row)
        raise InputError(f"{origin}: input v{k + 1} has min = max: a domain of no width, which no fit of readings "
                         "that vary writes")
    named = [f"v{k}" for k in range(1, len(lo) + 1)]  # the columns the model reads, as to_dict writes them
    if inputs.get("names", named) != named:
        raise InputError(f"{origin}: inputs.names must be {named[0]}..{named[-1]} for its {len(lo)} inputs, got "
                         f"{inputs['names']!r:.60}")
    fit = data.get("fit", {})
    _check_fit_notes(fit, origin)
    refine = None if "refine" not in data else Refinement.from_dict(data["refine"], len(lo), origin)
    try:
        return Model(np.array(lo), np.array(hi), tuple(eqs), units, fit, harmonics, refine)
    except InputError as exc:  # the object's own checks name no file
        raise InputError(f"{origin}: {str(exc).removeprefix('model: ')}") from None


# the fit notes' parts the tools read (the rest is a record for people): each an object where present
_NOTE_TABLES = ("settings", "noise", "precision", "outputs", "family", "held_out")
_HELD_OUT_TABLES = ("box", "errors", "posterior", "uncalibrated")


def _check_fit_notes(fit, origin: str) -> None:
    """InputError (one line) when the fit notes' parts that commands read are not as ``fitgen fit`` writes them
    (an edit by hand): read later, they would fail far from the file."""
    def refuse(where: str, what: str, got) -> None:
        raise InputError(f"{origin}: fit{where} must be {what}, got {got!r:.60}: its fit notes are not as fitgen "
                         "fit writes them (fit the model again, or restore the file)")

    if not isinstance(fit, dict):
        refuse("", "an object", fit)
    for key in _NOTE_TABLES:
        if key in fit and not isinstance(fit[key], dict):
            refuse(f".{key}", "an object", fit[key])
    held = fit.get("held_out", {})
    for key in _HELD_OUT_TABLES:
        if key in held and not isinstance(held[key], dict):
            refuse(f".held_out.{key}", "an object", held[key])
    for name, pair in held.get("box", {}).items():
        ok = isinstance(pair, list) and len(pair) == 2 and all(map(is_finite_number, pair)) and pair[0] <= pair[1]
        if not ok or max(map(abs, pair)) > BOX_LIMIT:  # mm or deg: past it no sensor's pose, and C's bounds overflow
            refuse(f".held_out.box.{name}", f"[low, high] (finite, within +-{BOX_LIMIT:g}, low <= high)", pair)
    if "rest" in held and not (isinstance(held["rest"], list) and all(map(is_finite_number, held["rest"]))):
        refuse(".held_out.rest", "a list of readings", held["rest"])
    if "rest_spread" in held and not (isinstance(held["rest_spread"], list)
                                      and all(is_finite_number(x) and x >= 0 for x in held["rest_spread"])):
        refuse(".held_out.rest_spread", "a list of spreads (>= 0)", held["rest_spread"])
    if held.get("labels", "stage") not in ("stage", "magnet"):  # whose displacements the set is simulated in
        refuse(".held_out.labels", "'stage' or 'magnet'", held["labels"])
    for key, low in (("poses", 1), ("seed", 0)):  # what verify and tactile-hil simulate the held-out set again from
        if key in held and (isinstance(held[key], bool) or not isinstance(held[key], int)
                            or not low <= held[key] < 2 ** 63):
            refuse(f".held_out.{key}", f"a whole number >= {low}", held[key])
    if not isinstance(fit.get("sensor_sha256"), (str, type(None))):
        refuse(".sensor_sha256", "a hash (text)", fit["sensor_sha256"])

    def figure(x) -> bool:  # what report prints and check compares: an error or a noise, never negative
        return is_finite_number(x) and x >= 0

    for key in ("device", "data", "added"):
        if fit.get("noise", {}).get(key) is not None and not figure(fit["noise"][key]):
            refuse(f".noise.{key}", "a noise figure (a number >= 0)", fit["noise"][key])
    if "noise" in held and not figure(held["noise"]):
        refuse(".held_out.noise", "a noise figure (a number >= 0)", held["noise"])
    for precision, outputs in held.get("errors", {}).items():
        for output, figures in (outputs.items() if isinstance(outputs, dict) else [("", outputs)]):
            where = f".held_out.errors.{precision}" + (f".{output}" if output else "")
            if isinstance(figures, str) and output:  # why a precision has none ('unavailable')
                continue
            if not isinstance(figures, dict):
                refuse(where, "an object of error figures", figures)
            for name, x in figures.items():
                if not figure(x):
                    refuse(f"{where}.{name}", "an error figure (a number >= 0)", x)


def _term(text, where: str) -> Term:
    if not isinstance(text, str):
        raise InputError(f"{where}.terms: {text!r} is not a term (a string is expected)")
    try:
        return parse_term(text)
    except InputError as exc:
        raise InputError(f"{where}.terms: {exc}") from None


def _validate(m: Model, origin: str) -> None:
    if m.input_min.ndim != 1 or m.input_min.shape != m.input_max.shape or m.n_inputs < 1:
        raise InputError(f"{origin}: the input domain must give min and max for each of 1 or more inputs")
    if not (np.all(np.isfinite(m.input_min)) and np.all(np.isfinite(m.input_max))):
        raise InputError(f"{origin}: the input domain must be finite")
    if np.any(m.input_min > m.input_max):
        k = int(np.argmax(m.input_min > m.input_max)) + 1
        raise InputError(f"{origin}: input v{k} has min > max")
    names = [e.name for e in m.equations]
    if not names:
        raise InputError(f"{origin}: no outputs")
    for n in names:
        if n not in POSE_NAMES:
            raise InputError(f"{origin}: unknown output {n!r} (outputs are {', '.join(POSE_NAMES)})")
    if names != sorted(names, key=POSE_NAMES.index) or len(set(names)) != len(names):
        raise InputError(f"{origin}: outputs must be distinct and in the order {','.join(POSE_NAMES)}")
    if m.refine is not None:
        if tuple(names) != POSE_NAMES:
            raise InputError(f"{origin}: a refinement estimates the whole pose: it needs the outputs "
                             f"{','.join(POSE_NAMES)}, the model has {','.join(names)}")
        m.refine.validate(m.n_inputs, f"{origin}: refine")
    for e in m.equations:
        if len(set(e.terms)) != len(e.terms):
            raise InputError(f"{origin}: output {e.name} lists a term twice")
        for t in e.terms:
            if t.harm:
                if m.harmonics is None:
                    raise InputError(f"{origin}: output {e.name} term {t.text} needs inputs.harmonics")
                missing = [f for f in monomial_factors(t.harm) if f not in m.harmonics.symbols]
                if missing:
                    raise InputError(f"{origin}: output {e.name} term {t.text}: the ring has no {missing[0]}")
                if not np.sum(m.input_min) > 0:
                    raise InputError(f"{origin}: output {e.name} term {t.text} needs the inputs' sum > 0, "
                                     f"but the domain's lowest sum is {float(np.sum(m.input_min))!r}")
                continue
            if t.element > m.n_inputs:
                raise InputError(f"{origin}: output {e.name} term {t.text} refers to input v{t.element}; "
                                 f"the model has {m.n_inputs}")
            if t.needs_positive and not m.input_min[t.element - 1] > 0:
                raise InputError(f"{origin}: output {e.name} term {t.text} needs v{t.element} > 0, "
                                 f"but its domain starts at {float(m.input_min[t.element - 1])!r}")
            if t.mult and (t.mult not in names or names.index(t.mult) >= names.index(e.name)):
                raise InputError(f"{origin}: output {e.name} term {t.text} needs output {t.mult} "
                                 "computed before it")
