"""Estimate engines: the Python evaluator, or the generated C header built as a shared library (ctypes).

Both take one row of element readings and give (outputs, status) with the status
of the C API: 0 inside the fitted domain, a bit mask of clamped inputs, -1 for a
non-finite input. The C engine runs the very code the firmware compiles: the
header from ``fitgen.c.codegen.write_header``, included with ``TM_API`` defined
empty so that ``tm_estimate`` is exported, built with the project's warning flags
and ``-shared -fPIC -O2``.
"""

from __future__ import annotations

import ctypes
import tempfile
from pathlib import Path

import numpy as np

from fitgen.c.codegen import PRECISIONS, write_header
from fitgen.base.errors import InputError
from fitgen.equations.model import Model

from fitgen.c.compiled import compile_checked

ENGINES = ("python", "c")


class PythonEngine:
    name = "python"

    def __init__(self, model: Model, precision: str = "double"):
        """``precision`` float: the float header's arithmetic, bit for bit (a run of the C engine in float)."""
        self.model, self.precision = model, precision
        self.n_inputs, self.n_outputs = model.n_inputs, len(model.equations)

    def estimate(self, inputs: np.ndarray) -> tuple[np.ndarray, int]:
        out, status = self.model.predict(np.asarray(inputs, dtype=float).reshape(1, -1), with_status=True,
                                         precision=self.precision)
        return out[0], int(status[0])

    def close(self) -> None:
        pass


_WRAPPER = """/* {p}_shared.c: {p}_model.h with external linkage, for a shared library */
#define {u}_API
#include "{p}_model.h"

int {p}_n_inputs(void);
int {p}_n_outputs(void);
const char *{p}_model_hash(void);
int {p}_n_inputs(void) {{ return {u}_N_INPUTS; }}
int {p}_n_outputs(void) {{ return {u}_N_OUTPUTS; }}
const char *{p}_model_hash(void) {{ return {u}_MODEL_HASH; }}
"""


class CEngine:
    """``tm_estimate`` from the generated header, in a shared library loaded with ctypes."""

    name = "c"

    def __init__(self, model: Model, *, precision: str = "double", style: str = "table", prefix: str = "tm",
                 cc: str = "gcc", workdir: str | Path | None = None):
        if precision not in PRECISIONS:
            raise InputError(f"precision must be one of {', '.join(PRECISIONS)}, got {precision!r}")
        if precision == "fixed":
            raise InputError("the C engine takes input values (a double or float build); a fixed-point build takes "
                             "ADC codes: check it with tactile-host verify --precision fixed")
        self.model, self.precision = model, precision
        self.n_inputs, self.n_outputs = model.n_inputs, len(model.equations)
        self._tmp = None
        if workdir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="tactile-engine-")
            workdir = self._tmp.name
        self.dir = Path(workdir)
        write_header(model, self.dir, precision, style, prefix)
        src = self.dir / f"{prefix}_shared.c"
        src.write_text(_WRAPPER.format(p=prefix, u=prefix.upper()))
        self.library = self.dir / f"lib{prefix}_model.so"
        compile_checked(cc, [src], self.library, self.dir, ["-shared", "-fPIC"])
        lib = ctypes.CDLL(str(self.library))
        for name in ("n_inputs", "n_outputs"):
            getattr(lib, f"{prefix}_{name}").restype = ctypes.c_int
        getattr(lib, f"{prefix}_model_hash").restype = ctypes.c_char_p
        built = (getattr(lib, f"{prefix}_n_inputs")(), getattr(lib, f"{prefix}_n_outputs")(),
                 getattr(lib, f"{prefix}_model_hash")().decode())
        if built != (self.n_inputs, self.n_outputs, model.sha256):
            raise RuntimeError(f"the built library does not match the model: {built}")
        self._lib = lib
        self._fn = getattr(lib, f"{prefix}_estimate")
        self._fn.restype = ctypes.c_int
        self._fn.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
        dtype = np.float64 if precision == "double" else np.float32
        self._in = np.zeros(self.n_inputs, dtype=dtype)
        self._out = np.zeros(self.n_outputs, dtype=dtype)
        self._in_p = self._in.ctypes.data
        self._out_p = self._out.ctypes.data

    def estimate(self, inputs: np.ndarray) -> tuple[np.ndarray, int]:
        self._in[:] = inputs
        status = self._fn(self._in_p, self._out_p)
        return self._out.astype(float), status

    def close(self) -> None:
        if self._tmp is not None:
            self._tmp.cleanup()  # the loaded library stays mapped
            self._tmp = None


def make_engine(kind: str, model: Model, **kw):
    if kind == "python":
        return PythonEngine(model)
    if kind == "c":
        return CEngine(model, **kw)
    raise InputError(f"engine must be one of {', '.join(ENGINES)}, got {kind!r}")
