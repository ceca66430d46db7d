"""Run R's ``step()`` on the same columns, for tests and benchmarks (needs Rscript)."""

from __future__ import annotations

import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

_R_SCRIPT = r"""
args <- commandArgs(trailingOnly = TRUE)
d <- read.csv(args[1])
init <- readLines(args[2])
k <- as.numeric(args[3])
upper <- as.formula(paste("~", paste(setdiff(names(d), "y"), collapse = " + ")))
start <- if (length(init) && nzchar(init[1])) paste("y ~", paste(init, collapse = " + ")) else "y ~ 1"
t0 <- proc.time()[["elapsed"]]
fit <- step(lm(as.formula(start), data = d), scope = list(lower = ~1, upper = upper),
            direction = "both", k = k, trace = 0, steps = 1000)
t1 <- proc.time()[["elapsed"]]
cat(attr(terms(fit), "term.labels"), sep = "\n", file = args[4])
cat(sprintf("%.17g\n%.17g\n%d\n", extractAIC(fit, k = k)[2], t1 - t0, nrow(fit$anova)), file = args[5])
cat(sprintf("%.17g", fit$anova$AIC), sep = "\n", file = args[6])
"""


def have_r() -> bool:
    return shutil.which("Rscript") is not None


def r_step(columns: np.ndarray, y: np.ndarray, initial: list[int], k: float = 2.0) -> dict:
    """R's step(lm(y ~ initial), scope = ~all columns, direction = "both", k) on the columns.

    Returns {"selected": [column indices in R's term order], "aic": extractAIC, "seconds": time
    inside R for step() alone, "steps": rows of R's anova table, "trace": its AIC column, the start first}.
    """
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        names = [f"c{j}" for j in range(columns.shape[1])]
        table = np.column_stack([columns, y])
        lines = [",".join(names + ["y"])] + [",".join(map(repr, row)) for row in table.tolist()]
        (tmp / "d.csv").write_text("\n".join(lines) + "\n")
        (tmp / "init.txt").write_text("\n".join(names[j] for j in initial) + "\n")
        (tmp / "s.R").write_text(_R_SCRIPT)
        t0 = time.perf_counter()
        proc = subprocess.run(["Rscript", "--vanilla", str(tmp / "s.R"), str(tmp / "d.csv"), str(tmp / "init.txt"),
                               repr(float(k)), str(tmp / "terms.txt"), str(tmp / "aic.txt"), str(tmp / "trace.txt")],
                              capture_output=True, text=True, timeout=3600)
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            raise RuntimeError(f"Rscript failed: {proc.stderr.strip()}")
        labels = [ln for ln in (tmp / "terms.txt").read_text().splitlines() if ln]
        aic, seconds, steps = (tmp / "aic.txt").read_text().split()
        trace = [float(x) for x in (tmp / "trace.txt").read_text().split()]
    return {"selected": [int(lbl[1:]) for lbl in labels], "aic": float(aic), "seconds": float(seconds),
            "wall": wall, "steps": int(steps), "trace": trace}
