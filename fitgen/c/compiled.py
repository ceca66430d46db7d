"""A generated header compiled with a C compiler, evaluated through a pipe: C answers next to numpy's."""

from __future__ import annotations

import shlex
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from fitgen.c.codegen import _env, render_fixed_header, write_header
from fitgen.base.children import run_captured
from fitgen.base.errors import InputError
from fitgen.equations.model import Model

WARNING_FLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-Wdouble-promotion", "-Wfloat-conversion"]


def compile_checked(cc: str, sources: list[Path], output: Path, include: Path, extra: list[str] | None = None,
                    link: bool = True) -> None:
    """Compile with the project's warning flags; a warning is an error (InputError with the compiler's text)."""
    tool = tool_command(cc, "compiler")
    # the flags in `cc` after the project's, so that the user's -O3 or -std=gnu99 is the build that is checked
    cmd = tool[:1] + WARNING_FLAGS + ["-O2"] + tool[1:] + ["-I", str(include)] + (extra or [])
    cmd += [str(s) for s in sources] + (["-o", str(output), "-lm"] if link else ["-c", "-o", str(output)])
    proc = run_tool(cmd, "compiler", None)
    if proc.returncode != 0:
        raise InputError(f"{cc} failed on the generated code: {first_error(proc.stderr)}")
    if not output.is_file():  # `--cc true`: a status 0 and nothing built
        raise InputError(f"the compiler {cc!r} exited with status 0 but wrote no {output.name}: give a C compiler")


def first_error(stderr: str) -> str:
    """The compiler's first line that says error (its first lines are often 'In file included from')."""
    lines = [ln.strip() for ln in stderr.strip().splitlines() if ln.strip()] or ["(no message)"]
    return next((ln for ln in lines if "error" in ln.lower()), lines[0])


def tool_command(text: str, what: str, hint: str = "") -> list[str]:
    """``text`` split as a shell would, its program found on PATH; InputError (with ``hint``) otherwise."""
    try:
        tool = shlex.split(text)
    except ValueError as exc:
        raise InputError(f"{what} {text!r}: {exc}") from None
    if not tool:
        raise InputError(f"the {what} is empty")
    if shutil.which(tool[0]) is None:
        raise InputError(f"{what} {tool[0]!r} not found" + (f" ({hint})" if hint else ""))
    return tool


def run_tool(cmd: list[str], what: str, stdin: str | None, timeout: float = 600) -> subprocess.CompletedProcess:
    """Run ``cmd``; one line (InputError) when it cannot start or runs past ``timeout`` seconds."""
    try:
        return run_captured(cmd, input=stdin, timeout=timeout)
    except subprocess.TimeoutExpired:
        raise InputError(f"the {what} {cmd[0]} ran past {timeout:g} s") from None
    except OSError as exc:
        raise InputError(f"the {what} {cmd[0]} cannot run here ({exc.strerror or exc}); a cross compiler's "
                         "binaries need a runner (--runner qemu-arm, and -static in --cc)") from None


class CompiledModel:
    """The model's header built into a vector-runner binary; ``predict`` pipes inputs through it.

    ``runner`` prefixes the binary's command (e.g. ``qemu-arm``); ``cc`` may be a cross compiler
    with its flags (e.g. ``arm-linux-gnueabihf-gcc -static``).

    ``precision="fixed"``: the fixed-point header (``self.fixed`` is its
    :class:`~fitgen.equations.fixedmodel.FixedModel`; ``input_lsb``/``input_offset`` as for codegen,
    ``mul_bits`` the plan's multiply width, fitgen.equations.fixedpoint.build_fixed); ``predict`` then
    takes integer codes and answers the integer outputs.
    """

    def __init__(self, model: Model, precision: str = "double", style: str = "table", prefix: str = "tm",
                 cc: str = "gcc", runner: str = "", workdir: str | Path | None = None, cflags: list[str] | None = None,
                 fma: bool = False, input_lsb: float | None = None, input_offset: float | None = None,
                 mul_bits: int = 32):
        self.model, self.precision, self.style, self.prefix, self.fma = model, precision, style, prefix, fma
        self.runner = tool_command(runner, "runner") if runner else []
        self.fixed = None
        if precision == "fixed":
            from fitgen.equations.inputscale import plan_at

            if fma:
                raise InputError("--fma does not apply to fixed point")
            self.fixed = plan_at(model, input_lsb, input_offset, mul_bits)[0]
            text = render_fixed_header(self.fixed, prefix)
        self._tmp = None
        if workdir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="fitgen-c-")
            workdir = self._tmp.name
        self.dir = Path(workdir)
        try:  # a build that fails or is interrupted leaves no folder behind: no `with` holds this object yet
            self._build(model, prefix, cc, cflags, precision, style, fma, text if self.fixed is not None else None)
        except BaseException:
            self.close()
            raise

    def _build(self, model: Model, prefix: str, cc: str, cflags, precision: str, style: str, fma: bool,
               fixed_text: str | None) -> None:
        if fixed_text is not None:
            self.header = self.dir / f"{prefix}_model.h"
            self.header.write_text(fixed_text)
        else:
            self.header = write_header(model, self.dir, precision, style, prefix, fma)
        runner_template = "vector_main_fixed.c.j2" if self.fixed is not None else "vector_main.c.j2"
        main = _env().get_template(runner_template).render(P=prefix, U=prefix.upper(),
                                                           version=model.to_dict()["generator"])
        src = self.dir / f"{prefix}_vectors.c"
        src.write_text(main)
        self.binary = self.dir / f"{prefix}_vectors"
        compile_checked(cc, [src], self.binary, self.dir, cflags)

    def _run(self, text: str, n: int) -> list[list[str]]:
        proc = run_tool(self.runner + [str(self.binary)], "vector runner", text)
        runner = " ".join(self.runner + [self.binary.name])
        if proc.returncode != 0:
            said = " ".join(proc.stderr.split())[:200] or "no message"
            hint = ("; link it statically: -static in --cc" if self.runner and "ld-linux" in said else
                    # the runner emulates another machine and --cc built for this one
                    "; build for the runner's machine with a cross-compiler, e.g. --cc 'arm-linux-gnueabihf-gcc "
                    "-static' for qemu-arm" if self.runner and "Invalid ELF image" in said else "")
            raise InputError(f"the vector runner {runner} failed (exit status {proc.returncode}: {said}){hint}")
        rows = [ln.split() for ln in proc.stdout.splitlines()]
        if len(rows) != n:
            raise InputError(f"the vector runner {runner} answered {len(rows)} lines for {n} vectors")
        return rows

    def predict_codes(self, codes) -> tuple[np.ndarray, np.ndarray]:
        """Fixed point: (integer outputs (n, K) int64, status (n,)) for int32 codes (n, N), exact both ways."""
        if self.fixed is None:
            raise InputError("predict_codes needs a fixed-point build (precision='fixed')")
        self.fixed.clamp_codes(codes)  # whole numbers within int32, the right count per row (InputError otherwise)
        codes = np.atleast_2d(np.asarray(codes)).astype(np.int64)
        text = "\n".join(" ".join(str(int(x)) for x in row) for row in codes) + "\n"
        rows = self._run(text, len(codes))
        status = np.array([int(r[0]) for r in rows], dtype=np.int64)
        out = np.array([[int(x) for x in r[1:]] for r in rows], dtype=np.int64).reshape(len(rows), -1)
        return out, status

    def predict(self, inputs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(outputs (n, K), status (n,)) from the C code, read back exactly (hex floats).

        Fixed point: ``inputs`` are integer codes and the outputs are converted to real values.
        """
        if self.fixed is not None:
            out, status = self.predict_codes(inputs)
            return self.fixed.to_real(out), status
        inputs = np.atleast_2d(np.asarray(inputs, dtype=float))
        text = "\n".join(" ".join(float(x).hex() if np.isfinite(x) else ("nan" if np.isnan(x) else
                                                                           ("inf" if x > 0 else "-inf"))
                                  for x in row) for row in inputs) + "\n"
        rows = self._run(text, len(inputs))
        status = np.array([int(r[0]) for r in rows])
        out = np.array([[float.fromhex(x) for x in r[1:]] for r in rows])
        return out, status

    def close(self):
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
