"""Benchmark of the stepwise fit: against R's step() and a plain refit loop, and in rows.

Run: ``python bench/fit.py > /tmp/fitbench.md`` (markdown on stdout, progress on stderr; about 7 minutes
on 2 cores, docs/fit-benchmark.md, most of it in part 4, R and the plain loop). Needs Rscript (apt:
r-base-core) for part 1, checked before anything runs; ``--rows-only`` and ``--command-only`` do not.

Part 1, the paper grid (1,875 poses, no noise), outputs dx, dy, dz, thx, thy; the
rotations get the d-columns from the stage-1 estimates of the exact fit (FitSettings.exact()),
as tests/test_stepwise.py does:
  ours   stepwise(X, y, init) including its compress() of the rows, median of 11 runs
         after one warm-up call (the first LAPACK call of a process pays a start-up cost);
  R      step() as rstep.r_step runs it; the seconds inside R around
         step(lm(...)) alone (no R start-up, no CSV reading), median of up to 3 runs
         (1 if a run takes more than 3 s);
  naive  stepwise_reference (refits every candidate model by lstsq on all rows),
         median of up to 3 runs (1 if a run takes more than 5 s), on one BLAS thread
         as fitgen's own linear algebra runs (R's reference BLAS is single-threaded too;
         two OpenBLAS threads on 2 shared cores made it 9-45x slower in a trial).
All three start from the same initial terms on the same design matrix X.

Part 2, rows: fit_output("dz", ...) on random poses with 0.0005 noise, 1,875 / 20,000 /
200,000 rows, median of 3 after a warm-up run; the timed call builds the candidate design matrix,
compresses, searches, refits from the compressed triangle and computes the training error. Simulation
is not timed. Memory at 200,000 rows: tracemalloc peak and the process max RSS.

Part 3, rows without limit: fit_output("dz") at 200,000 and 2,000,000 rows (an hour of capture at
860 samples/s), each in a fresh process: time, the fit's own peak and the process's max RSS.
``python bench/fit.py --rows-only`` runs this part alone.

Part 4, the command: the whole `fitgen fit DATA -o MODEL` as a user runs it, the default (noise-aware,
float, family auto, held-out figures) against `--noise 0` (the paper's procedure), at 1,875 / 20,000 /
200,000 random rows, each run a fresh process, the two alternating; median time and peak RSS of each and
their ratios (issue 20: the default within 3x the time and 1.5x the peak memory at 20,000 rows).
``python bench/fit.py --command-only`` runs this part alone; ``--baseline DIR`` adds both commands run
with the fitgen source tree at DIR (e.g. ``git archive COMMIT | tar -x -C DIR``) and compares its terms.
"""

from __future__ import annotations

import os
import platform
import resource
import statistics
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np
import scipy
from threadpoolctl import threadpool_limits

from benchutil import need_tools, parser
from fitgen.fitting.fit import FitSettings, fit_model, fit_output
from fitgen.equations.model import Model

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))  # R's step(), the tests' peer
from rstep import r_step  # noqa: E402
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import DEFAULT_RANGES, PAPER_GRIDS, grid_poses, pose_rng, random_poses, simulate
from fitgen.fitting.stepwise import compress, refit, stepwise, stepwise_reference
from fitgen.equations.terms import DISPLACEMENTS, candidate_terms, design_matrix, initial_terms

OURS_REPEATS = 11
NAIVE_MAX_REPEATS = 3
NAIVE_REPEAT_IF_UNDER = 5.0  # seconds: repeat the plain loop only when one run is this quick
R_MAX_REPEATS = 3
R_REPEAT_IF_UNDER = 3.0  # seconds inside step(): repeat R only when one run is this quick
TIE_RTOL = 1e-12  # same terms set aside, AICs this close are a tie broken by rounding
SCALING_ROWS = (1_875, 20_000, 200_000)
SCALING_REPEATS = 3
SCALING_OUTPUT = "dz"
NOISE = 0.0005
SEED = 1
AIC_RTOL = 1e-6

PAPER = load_sensor("paper")
T_START = time.perf_counter()


def log(msg: str) -> None:
    print(f"[{time.perf_counter() - T_START:6.1f} s] {msg}", file=sys.stderr, flush=True)


def timed(fn, *args, **kw):
    t0 = time.perf_counter()
    out = fn(*args, **kw)
    return time.perf_counter() - t0, out


def median_time(fn, repeats: int):
    times, out = [], None
    for _ in range(repeats):
        t, out = timed(fn)
        times.append(t)
    return statistics.median(times), times, out


def table(header: list[str], rows: list[list], align: str | None = None) -> str:
    align = align or "l" + "r" * (len(header) - 1)
    cells = [[str(c) for c in r] for r in rows]
    widths = [max(len(h), *(len(r[i]) for r in cells)) for i, h in enumerate(header)]

    def line(vals):
        return "| " + " | ".join(v.ljust(w) if a == "l" else v.rjust(w) for v, w, a in zip(vals, widths, align)) + " |"

    rule = "| " + " | ".join(("-" * (w - 1) + ":") if a == "r" else "-" * w for w, a in zip(widths, align)) + " |"
    return "\n".join([line(header), rule] + [line(r) for r in cells])


def blas_info() -> str:
    try:
        from threadpoolctl import threadpool_info

        libs = {(i["internal_api"], i.get("version"), i["num_threads"]) for i in threadpool_info()}
        return ", ".join(f"{api} {ver} ({n} threads)" for api, ver, n in sorted(libs, key=str))
    except Exception:  # threadpoolctl missing: not essential
        return "unknown"


def r_version() -> str:
    try:
        out = subprocess.run(["Rscript", "--vanilla", "-e", "cat(R.version.string)"], capture_output=True,
                             text=True, timeout=60)
        return out.stdout.strip() or "unknown"
    except Exception:
        return "unknown"


def same(sel_a, aic_a, sel_b, aic_b) -> bool:
    return sorted(sel_a) == sorted(sel_b) and abs(aic_a - aic_b) <= AIC_RTOL * max(abs(aic_a), abs(aic_b), 1e-300)


def problem(ds, output, d=None):
    """As tests/test_stepwise.py's _problem: candidates, design matrix, target, initial indices."""
    cands = candidate_terms(ds.n_inputs, output, d_terms=d is not None, positive=ds.inputs.min(axis=0) > 0)
    X = design_matrix(cands, ds.inputs, d)
    init = [cands.index(t) for t in initial_terms(ds.n_inputs)]
    return cands, X, ds.target(output), init


# ---------------------------------------------------------------------------------------------- part 1


def part_paper_grid() -> tuple[str, dict]:
    ds = simulate(PAPER, grid_poses(PAPER_GRIDS["paper-sim"]))
    log(f"paper grid: {ds.n_rows} rows")
    # the very first search of the process, for the record (LAPACK and scipy.linalg start-up)
    _, X0, y0, init0 = problem(ds, "dx")
    cold, _ = timed(stepwise, X0, y0, init0)
    warm, _ = timed(stepwise, X0, y0, init0)  # the warm-up call the brief asks for
    log(f"first stepwise call of the process {cold * 1e3:.1f} ms, second {warm * 1e3:.1f} ms")

    # the d-columns as tests/test_stepwise.py makes them: the paper's procedure (R's step()), no noise rows
    t_model, model = timed(fit_model, ds, settings=FitSettings.exact())
    d = Model(model.input_min, model.input_max, tuple(model.equation(x) for x in DISPLACEMENTS)).predict(ds.inputs)
    log(f"fit_model (5 outputs, two stages) {t_model:.2f} s; stage-1 d estimates ready")

    rows, notes, results = [], [], {}
    for out in ds.target_names:
        cands, X, y, init = problem(ds, out, d if out in ("thx", "thy") else None)
        t_ours, ours_times, ours = median_time(lambda: stepwise(X, y, init), OURS_REPEATS)
        t_comp, _, _ = median_time(lambda: compress(X, y), OURS_REPEATS)
        log(f"{out}: X {X.shape[0]}x{X.shape[1]}, ours median {t_ours * 1e3:.1f} ms "
            f"(runs {', '.join(f'{t * 1e3:.0f}' for t in ours_times)} ms), compress alone {t_comp * 1e3:.1f} ms")
        r_times = []
        while len(r_times) < R_MAX_REPEATS:
            rr = r_step(X, y, init)
            r_times.append(rr["seconds"])
            log(f"{out}: R step() run {len(r_times)}: {rr['seconds']:.2f} s inside R "
                f"({rr['wall']:.2f} s with R start-up and CSV)")
            if rr["seconds"] > R_REPEAT_IF_UNDER:
                break
        t_r = statistics.median(r_times)
        naive_times = []
        while len(naive_times) < NAIVE_MAX_REPEATS:
            with threadpool_limits(limits=1, user_api="blas"):
                t, naive = timed(stepwise_reference, X, y, init)
            naive_times.append(t)
            log(f"{out}: naive loop run {len(naive_times)}: {t:.2f} s")
            if t > NAIVE_REPEAT_IF_UNDER:
                break
        t_naive = statistics.median(naive_times)

        ok_r = same(ours.selected, ours.aic, rr["selected"], rr["aic"])
        ok_n = same(ours.selected, ours.aic, naive.selected, naive.aic)
        steps = len(ours.trace) - 1
        r_steps = rr["steps"] - 1  # R's anova table has a row for the start

        def verdict(ok, aic):
            if ok:
                return "yes"
            return "tie" if abs(ours.aic - aic) <= TIE_RTOL * abs(aic) else "no"

        ident = "yes" if ok_r and ok_n else (f"R: {verdict(ok_r, rr['aic'])}, "
                                             f"naive: {verdict(ok_n, naive.aic)}")
        for who, sel, aic, ok in (("R step()", rr["selected"], rr["aic"], ok_r),
                                  ("naive loop", naive.selected, naive.aic, ok_n)):
            if not ok:
                only_ours = sorted(set(ours.selected) - set(sel))
                only_other = sorted(set(sel) - set(ours.selected))
                rel = abs(ours.aic - aic) / abs(aic)
                notes.append(f"{out}: ours and {who} differ: ours has "
                             f"{', '.join(cands[j].text for j in only_ours) or '-'}, {who} has "
                             f"{', '.join(cands[j].text for j in only_other) or '-'}; AIC {ours.aic:.10f} vs "
                             f"{aic:.10f} (relative difference {rel:.1e})")
        if steps != r_steps:
            notes.append(f"{out}: ours took {steps} steps, R {r_steps}")
        results[out] = {"ours": t_ours, "ours_min": min(ours_times), "r": t_r, "r_runs": len(r_times),
                        "r_min": min(r_times), "naive": t_naive, "naive_runs": len(naive_times), "compress": t_comp,
                        "steps": steps, "terms": len(ours.selected), "cands": X.shape[1], "ok": ident == "yes"}
        rows.append([out, f"{len(ours.selected)} of {X.shape[1]}", steps, f"{t_ours * 1e3:.1f}",
                     f"{t_r * 1e3:.0f}", f"{t_naive * 1e3:.0f}", f"{t_r / t_ours:.0f}x",
                     f"{t_naive / t_ours:.0f}x", ident])

    tot = {k: sum(r[k] for r in results.values()) for k in ("ours", "r", "naive")}
    rows.append(["all 5", "", sum(r["steps"] for r in results.values()), f"{tot['ours'] * 1e3:.1f}",
                 f"{tot['r'] * 1e3:.0f}", f"{tot['naive'] * 1e3:.0f}", f"{tot['r'] / tot['ours']:.0f}x",
                 f"{tot['naive'] / tot['ours']:.0f}x", ""])

    md = ["## 1. Paper grid (1,875 rows): the search against R's step() and the plain refit loop", ""]
    md.append(table(["output", "terms selected", "steps", "ours [ms]", "R step() [ms]", "naive loop [ms]",
                     "speed-up vs R", "speed-up vs naive", "identical"], rows))
    md.append("")
    md.append(f"ours: median of {OURS_REPEATS} runs of stepwise(X, y, init) including compress(), after a warm-up "
              f"call; R: time inside R around step(lm(...)) alone, median of up to {R_MAX_REPEATS} runs (1 when a "
              f"run exceeds {R_REPEAT_IF_UNDER:.0f} s); naive: stepwise_reference on one BLAS thread, median of up "
              f"to {NAIVE_MAX_REPEATS} runs (1 when a run exceeds {NAIVE_REPEAT_IF_UNDER:.0f} s). 'identical': "
              f"same sorted indices and AIC within {AIC_RTOL:g} relative, ours vs R and ours vs naive; 'tie': "
              f"different terms with AICs equal within {TIE_RTOL:g} relative. 'all 5': sums.")
    md.append("")
    md.append(table(["output", "ours median [ms]", "ours min [ms]", "compress() alone [ms]", "compress share",
                     "R runs", "R min [ms]", "R min / ours min", "naive runs"],
                    [[o, f"{r['ours'] * 1e3:.1f}", f"{r['ours_min'] * 1e3:.1f}", f"{r['compress'] * 1e3:.1f}",
                      f"{100 * r['compress'] / r['ours']:.0f} %", r["r_runs"], f"{r['r_min'] * 1e3:.0f}",
                      f"{r['r_min'] / r['ours_min']:.0f}x", r["naive_runs"]] for o, r in results.items()]))
    md.append("")
    md.append(f"First stepwise() call of the process (dx, cold): {cold * 1e3:.1f} ms; the next call: "
              f"{warm * 1e3:.1f} ms. fit_model on the grid (exact, 5 outputs, two stages, refits): {t_model:.2f} s, 1 run.")
    if notes:
        md.append("")
        md.append("Differences:")
        md.append("")
        md += [f"- {n}" for n in notes]
    md.append("")
    worst = min(results.items(), key=lambda kv: kv[1]["r"] / kv[1]["ours"])
    md.append(f"Target >= 50x faster than R per output: {'met' if worst[1]['r'] / worst[1]['ours'] >= 50 else 'NOT met'} "
              f"(lowest: {worst[0]}, {worst[1]['r'] / worst[1]['ours']:.0f}x).")
    return "\n".join(md), results


# ---------------------------------------------------------------------------------------------- part 2


def _fit(ds):
    return fit_output(SCALING_OUTPUT, ds.inputs, ds.target(SCALING_OUTPUT), None, settings=FitSettings(),
                      positive=ds.inputs.min(axis=0) > 0)


def _phases(ds):
    """Time (median of SCALING_REPEATS) of the pieces fit_output runs, in its order."""
    positive = ds.inputs.min(axis=0) > 0
    cands = candidate_terms(ds.n_inputs, SCALING_OUTPUT, positive=positive)
    init = [cands.index(t) for t in initial_terms(ds.n_inputs)]
    y = ds.target(SCALING_OUTPUT)
    t_dm, _, X = median_time(lambda: design_matrix(cands, ds.inputs), SCALING_REPEATS)
    t_c, _, A = median_time(lambda: compress(X, y), SCALING_REPEATS)
    t_s, _, res = median_time(lambda: stepwise(X, y, init, max_terms=ds.n_rows - 2, compressed=A), SCALING_REPEATS)
    t_r, _, _ = median_time(lambda: refit(A, res.selected), SCALING_REPEATS)
    return {"design matrix": t_dm, "compress": t_c, "search": t_s, "refit": t_r}


def max_rss() -> int:
    """The process's max resident set size so far, in bytes (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def _memory(ds):
    """Peak memory of one fit_output at this size: tracemalloc and the process max RSS."""
    positive = ds.inputs.min(axis=0) > 0
    cands = candidate_terms(ds.n_inputs, SCALING_OUTPUT, positive=positive)
    rss_before = max_rss()
    tracemalloc.start()
    base, _ = tracemalloc.get_traced_memory()
    tracemalloc.reset_peak()
    _fit(ds)
    _, peak = tracemalloc.get_traced_memory()
    # phase by phase (the same work, each peak above what is live when the phase starts)
    phase_peaks = {}
    y = ds.target(SCALING_OUTPUT)
    init = [cands.index(t) for t in initial_terms(ds.n_inputs)]

    def peak_of(name, fn):
        cur, _ = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        out = fn()
        phase_peaks[name] = tracemalloc.get_traced_memory()[1] - cur
        return out

    X = peak_of("design matrix", lambda: design_matrix(cands, ds.inputs))
    A = peak_of("compress", lambda: compress(X, y))
    res = peak_of("search", lambda: stepwise(X, y, init, max_terms=ds.n_rows - 2, compressed=A))
    peak_of("refit", lambda: refit(A, res.selected))
    tracemalloc.stop()
    rss_after = max_rss()
    return {"traced_peak": peak - base, "rss_before": rss_before, "rss_after": rss_after,
            "design_bytes": ds.n_rows * len(cands) * 8, "cands": len(cands), "phases": phase_peaks,
            "block_bytes": (1 << 14) * (len(cands) + 2) * 8}


def part_rows() -> str:
    rows, phase_rows, phases, prev = [], [], [], None
    mem = None
    for n in SCALING_ROWS:
        rss_pre_sim = max_rss()
        t_sim, ds = timed(simulate, PAPER, random_poses(n, DEFAULT_RANGES, pose_rng(SEED)), noise=NOISE, seed=SEED)
        rss_sim = max_rss()
        log(f"rows {n}: simulated in {t_sim:.2f} s (not timed)")
        _fit(ds)  # warm-up at this size (page faults of the first large allocations)
        t, times, fo = median_time(lambda ds=ds: _fit(ds), SCALING_REPEATS)
        log(f"rows {n}: fit_output {SCALING_OUTPUT} median {t:.3f} s (runs {', '.join(f'{x:.3f}' for x in times)})")
        ph = _phases(ds)
        log(f"rows {n}: phases " + ", ".join(f"{k} {v:.3f} s" for k, v in ph.items()))
        growth = ""
        if prev is not None:
            growth = f"{(t / prev[1]) / (n / prev[0]):.2f} (x{t / prev[1]:.1f} time for x{n / prev[0]:.1f} rows)"
        rows.append([f"{n:,}", fo.info["terms"], len(fo.info["steps"]) - 1, f"{t:.3f}", f"{1000 * t / n:.4f}",
                     growth])
        phase_rows.append([f"{n:,}"] + [f"{v:.3f}" for v in ph.values()])
        phases.append((n, ph))
        prev = (n, t)
        if n == SCALING_ROWS[-1]:
            log(f"rows {n}: memory run (tracemalloc on, not timed)")
            mem = _memory(ds)
            mem.update(rss_pre_sim=rss_pre_sim, rss_sim=rss_sim)
        del ds

    md = [f"## 2. Rows: fit_output(\"{SCALING_OUTPUT}\") on random poses, noise {NOISE} mT", ""]
    md.append(table(["rows", "terms", "steps", "seconds", "s per 1,000 rows", "time growth / row growth"], rows))
    md.append("")
    md.append(f"Median of {SCALING_REPEATS} runs after one warm-up run per size. Timed: the whole fit_output call "
              f"(candidate list, the candidate columns built and compressed block by block, search, refit, "
              f"training errors); "
              f"simulation excluded. Growth ratio <= 1: time grows no faster than the rows.")
    md.append("")
    md.append("Where it goes (the same pieces timed one by one, median of 3, seconds):")
    md.append("")
    for (n0, p0), (n1, p1) in zip(phases, phases[1:]):
        phase_rows.append([f"growth / row growth, {n0:,} to {n1:,}"]
                          + [f"{(p1[k] / p0[k]) / (n1 / n0):.2f}" for k in p0])
    md.append(table(["rows", "design matrix", "compress", "search", "refit"], phase_rows))
    md.append("")
    mb = 1e6
    md.append(f"### Memory at {SCALING_ROWS[-1]:,} rows ({mem['cands']} candidates)")
    md.append("")
    md.append(table(["measure", "MB", "x design matrix"], [
        ["full n x m candidate design matrix (float64)", f"{mem['design_bytes'] / mb:.1f}", "1.00"],
        ["tracemalloc peak during fit_output, above its start", f"{mem['traced_peak'] / mb:.1f}",
         f"{mem['traced_peak'] / mem['design_bytes']:.2f}"],
        ["design_matrix() alone, peak above its start", f"{mem['phases']['design matrix'] / mb:.1f}",
         f"{mem['phases']['design matrix'] / mem['design_bytes']:.2f}"],
        ["compress() alone (X already live)", f"{mem['phases']['compress'] / mb:.1f}",
         f"{mem['phases']['compress'] / mem['design_bytes']:.2f}"],
        ["stepwise() alone, on the triangle", f"{mem['phases']['search'] / mb:.3f}",
         f"{mem['phases']['search'] / mem['design_bytes']:.4f}"],
        ["refit() alone, on all rows (incl. X[:, selected])", f"{mem['phases']['refit'] / mb:.1f}",
         f"{mem['phases']['refit'] / mem['design_bytes']:.2f}"],
        ["one compress() block (16,384 rows x (m+2))", f"{mem['block_bytes'] / mb:.1f}",
         f"{mem['block_bytes'] / mem['design_bytes']:.2f}"],
        ["process max RSS before simulating the 200,000 rows", f"{mem['rss_pre_sim'] / mb:.1f}", ""],
        ["process max RSS after simulating them (no fit yet)", f"{mem['rss_sim'] / mb:.1f}", ""],
        ["process max RSS after the timed fits, before the memory run", f"{mem['rss_before'] / mb:.1f}", ""],
        ["process max RSS after the memory run", f"{mem['rss_after'] / mb:.1f}", ""],
    ], align="lrr"))
    md.append("")
    md.append("tracemalloc: bytes Python and numpy allocate (numpy reports its data buffers to tracemalloc), "
              "peak minus what was live when the fit started, so it is the fit's own working set; BLAS/LAPACK "
              "workspaces allocated in C outside numpy are not seen. Max RSS (getrusage ru_maxrss): the "
              "high-water mark of the whole process's resident memory since it started: interpreter, "
              "libraries, the simulated dataset, earlier parts of this benchmark, and the fits; its rise across "
              "the fits at this size is the fits' resident peak (it cannot fall, so the memory run, with "
              "the same peak, leaves it where the timed fits put it).")
    return "\n".join(md)


# ---------------------------------------------------------------------------------------------- part 3

LIMIT_ROWS = (200_000, 2_000_000)
_CHILD = r"""
import json, resource, sys, time, tracemalloc
import numpy as np
from fitgen.fitting.fit import FitSettings, fit_output
def status(key):
    for line in open("/proc/self/status"):
        if line.startswith(key + ":"):
            return int(line.split()[1]) * 1024

v, y = np.load(sys.argv[1] + ".v.npy"), np.load(sys.argv[1] + ".y.npy")
positive = v.min(axis=0) > 0
fit_output("dz", v[:2000], y[:2000], None, settings=FitSettings(), positive=positive)  # warm-up
rss_data = status("VmRSS")
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")  # resets the peak (VmHWM) to the current RSS: what follows is the fit's
t0 = time.perf_counter()
fo = fit_output("dz", v, y, None, settings=FitSettings(), positive=positive)
t = time.perf_counter() - t0
rss_fit = status("VmHWM")
tracemalloc.start()
base, _ = tracemalloc.get_traced_memory()
fit_output("dz", v, y, None, settings=FitSettings(), positive=positive)
peak = tracemalloc.get_traced_memory()[1] - base
print(json.dumps({"seconds": t, "terms": fo.info["terms"], "traced_peak": peak, "rss_data": rss_data,
                  "rss_fit": rss_fit, "data_bytes": v.nbytes + y.nbytes}))
"""


def part_rows_without_limit() -> str:
    """fit_output("dz") at 200,000 and 2,000,000 rows, each in a fresh process that loads the rows from
    a file: time, the fit's own peak (tracemalloc) and the process's max RSS with and without the fit."""
    import json
    import tempfile

    rows = []
    for n in LIMIT_ROWS:
        with tempfile.TemporaryDirectory() as tmp:
            path = f"{tmp}/rows"
            # simulated in blocks, so that the simulation's own peak stays out of the child's figures
            v, y = [], []
            for lo in range(0, n, 200_000):
                ds = simulate(PAPER, random_poses(min(200_000, n - lo), DEFAULT_RANGES, pose_rng(SEED + lo)),
                              noise=NOISE, seed=SEED + lo)
                v.append(ds.inputs)
                y.append(ds.target(SCALING_OUTPUT))
            np.save(path + ".v.npy", np.vstack(v))
            np.save(path + ".y.npy", np.concatenate(y))
            del v, y, ds
            log(f"rows without limit: {n:,} rows simulated; fitting in a fresh process")
            out = subprocess.run([sys.executable, "-c", _CHILD, path], capture_output=True, text=True, check=True)
        r = json.loads(out.stdout)
        rows.append((n, r))
        log(f"rows without limit: {n:,} rows in {r['seconds']:.1f} s, traced peak {r['traced_peak'] / 1e6:.1f} MB")
    mb = 1e6
    (n0, a), (n1, b) = rows
    md = [f"## 3. Rows without limit: fit_output(\"{SCALING_OUTPUT}\") at {n0:,} and {n1:,} rows", ""]
    md.append(table(["rows", "terms", "seconds", "time growth / row growth", "the rows (inputs, target), MB",
                     "fit's peak (tracemalloc), MB", "RSS before the fit, MB", "peak RSS during the fit, MB",
                     "the fit's resident peak, MB"], [
        [f"{n:,}", r["terms"], f"{r['seconds']:.1f}",
         "" if n == n0 else f"{(r['seconds'] / a['seconds']) / (n / n0):.2f}",
         f"{r['data_bytes'] / mb:.0f}", f"{r['traced_peak'] / mb:.1f}", f"{r['rss_data'] / mb:.0f}",
         f"{r['rss_fit'] / mb:.0f}", f"{(r['rss_fit'] - r['rss_data']) / mb:.0f}"] for n, r in rows]))
    md.append("")
    md.append("Each size in a fresh process that loads the simulated rows (noise 0.0005 mT, as measured data carry "
              "their noise: no noise rows are added, the float rounding rows are) from a file, one warm-up fit on "
              "2,000 rows, then one timed fit_output (candidate columns built 16,384 rows at a time and folded into "
              "the triangle, search, refit, the training error: predictions block by block, gathered for its "
              "p95) and one under tracemalloc. The fit's peak is what it allocates above what was live when it started. RSS before the fit: the "
              "process's resident memory with the interpreter, numpy, scipy, BLAS and the rows loaded; peak RSS "
              "during the fit: the high-water mark after resetting it (/proc/self/clear_refs) just before the fit; "
              "their difference is the fit's resident peak, BLAS workspaces included.")
    return "\n".join(md)


# ---------------------------------------------------------------------------------------------- part 4

COMMAND_ROWS = (1_875, 20_000, 200_000)
COMMAND_REPEATS = {1_875: 3, 20_000: 5, 200_000: 3}
BASELINE_REPEATS = {1_875: 3, 20_000: 3, 200_000: 1}
TIME_TARGET, MEMORY_TARGET = 3.0, 1.5  # issue 20: the default within 3x the exact fit's time, 1.5x its peak memory
# the user's `fitgen fit`: the console script's entry point, in a fresh interpreter that writes its
# peak RSS (VmHWM, since its exec) on exit: a child's ru_maxrss also counts the parent's pages at fork
_CLI = """import atexit, os, sys
def _peak():
    with open("/proc/self/status") as f, open(os.environ["FITBENCH_PEAK"], "w") as out:
        out.write(next(line for line in f if line.startswith("VmHWM:")).split()[1])
atexit.register(_peak)
from fitgen.app.cli import main
sys.argv[0] = "fitgen"
main()
"""


def _run_cli(args: list[str], tree: str | None = None) -> tuple[float, int]:
    """Wall time and peak RSS (bytes) of one fresh `fitgen ARGS` process; ``tree``: the fitgen source
    tree it imports (default: the one this process imported)."""
    import tempfile

    import fitgen

    tree = tree or os.path.dirname(os.path.dirname(os.path.abspath(fitgen.__file__)))
    with tempfile.TemporaryFile() as err, tempfile.NamedTemporaryFile("r") as peak:
        env = {**os.environ, "PYTHONPATH": tree, "FITBENCH_PEAK": peak.name}
        t0 = time.perf_counter()
        # run from the temporary folder: `python -c` puts the working folder first on the path
        p = subprocess.run([sys.executable, "-c", _CLI, *args], stdout=subprocess.DEVNULL, stderr=err, env=env,
                           cwd=tempfile.gettempdir())
        t = time.perf_counter() - t0
        if p.returncode:
            err.seek(0)
            sys.exit(f"fitgen {' '.join(args)} failed ({p.returncode}):\n{err.read().decode()[-2000:]}")
        return t, int(peak.read()) * 1024


def _model_summary(path: str) -> dict:
    import json

    m = json.load(open(path))
    return {"terms": {o["name"]: o["terms"] for o in m["outputs"]}, "family": m["fit"]["family"]["name"],
            "held_out": m["fit"].get("held_out", {}).get("errors", {})}


def part_command(baseline: str | None = None) -> str:
    """The whole `fitgen fit` command, default against `--noise 0`, in fresh processes, runs interleaved."""
    import tempfile

    rows, notes, verdict = [], [], {}
    with tempfile.TemporaryDirectory() as tmp:
        for n in COMMAND_ROWS:
            data = f"{tmp}/r{n}.csv"
            _run_cli(["simulate", "--sensor", "paper", "--random", str(n), "--seed", str(SEED), "-o", data])
            runs = {"default": [], "exact": [], "baseline": [], "baseline exact": []}
            plan = [("default", []), ("exact", ["--noise", "0"])]
            for i in range(COMMAND_REPEATS[n]):
                if baseline is not None and i < BASELINE_REPEATS[n]:
                    plan_i = plan + [("baseline", []), ("baseline exact", ["--noise", "0"])]
                else:
                    plan_i = plan
                for name, extra in plan_i:
                    out = f"{tmp}/{name.replace(' ', '-')}{n}.json"
                    t, rss = _run_cli(["fit", data, "-o", out, *extra], baseline if name.startswith("baseline") else None)
                    runs[name].append((t, rss))
                    log(f"command, {n:,} rows: {name} run {len(runs[name])}: {t:.2f} s, peak RSS {rss / 1e6:.0f} MB")
            med = {k: (statistics.median(t for t, _ in v), statistics.median(r for _, r in v))
                   for k, v in runs.items() if v}
            ours, exact = _model_summary(f"{tmp}/default{n}.json"), _model_summary(f"{tmp}/exact{n}.json")
            t_ratio, m_ratio = med["default"][0] / med["exact"][0], med["default"][1] / med["exact"][1]
            verdict[n] = (t_ratio, m_ratio)
            row = [f"{n:,}", f"{med['default'][0]:.2f}", f"{med['exact'][0]:.2f}", f"{t_ratio:.2f}",
                   f"{min(a[0] / b[0] for a, b in zip(runs['default'], runs['exact'])):.2f}-"
                   f"{max(a[0] / b[0] for a, b in zip(runs['default'], runs['exact'])):.2f}",
                   f"{med['default'][1] / 1e6:.0f}", f"{med['exact'][1] / 1e6:.0f}", f"{m_ratio:.2f}",
                   f"{ours['family']}, {sum(map(len, ours['terms'].values()))}",
                   f"{sum(map(len, exact['terms'].values()))}", len(runs["default"])]
            if baseline is not None:
                base = _model_summary(f"{tmp}/baseline{n}.json")
                same = base["terms"] == ours["terms"] and base["family"] == ours["family"]
                b, be = med["baseline"], med["baseline exact"]
                row += [f"{b[0]:.2f}", f"{be[0]:.2f}", f"{b[0] / be[0]:.2f}", f"{b[1] / 1e6:.0f}", f"{be[1] / 1e6:.0f}",
                        f"{b[1] / be[1]:.2f}", "yes" if same else "no"]
                if not same:
                    notes.append(_difference(n, base, ours))
            rows.append(row)
    header = ["rows", "default [s]", "--noise 0 [s]", "time ratio", "per-pair ratios", "default peak RSS [MB]",
              "--noise 0 peak RSS [MB]", "memory ratio", "default: family, terms", "--noise 0: terms", "runs"]
    if baseline is not None:
        header += ["baseline default [s]", "baseline --noise 0 [s]", "baseline time ratio",
                   "baseline default peak RSS [MB]", "baseline --noise 0 peak RSS [MB]", "baseline memory ratio",
                   "same terms as baseline"]
    md = ["## 4. The fit command: default (noise-aware, float, family auto) against `--noise 0`", ""]
    md.append(table(header, rows))
    md.append("")
    md.append(f"Each run a fresh process running `fitgen fit DATA -o MODEL` as a user does (imports, reading the CSV, "
              f"the fit, for the default both families and the validation that picks one, {2000:,} held-out poses, "
              f"writing the model); `fitgen simulate --sensor paper --random N --seed {SEED}` data (noise-free, so "
              f"the default adds the sensor's noise in expectation). Default and `--noise 0` runs alternate; "
              f"medians of {', '.join(f'{COMMAND_REPEATS[n]} ({n:,} rows)' for n in COMMAND_ROWS)} runs; time ratio: "
              f"default median / `--noise 0` median, per-pair ratios: the range over the consecutive pairs; peak RSS: "
              f"the process's own high-water mark since its start (VmHWM, read at exit), median.")
    if baseline is not None:
        md.append("")
        md.append(f"Baseline: the same two commands with the fitgen tree at `{baseline}`, in the same alternation "
                  f"(medians of {', '.join(f'{BASELINE_REPEATS[n]} ({n:,} rows)' for n in COMMAND_ROWS)} runs); "
                  f"'same terms': every output's terms and the family the same as this tree's default.")
    for n in notes:
        md += ["", n]
    t20, m20 = verdict[20_000]
    md.append("")
    md.append(f"Target, the default at 20,000 rows within {TIME_TARGET:g}x the `--noise 0` fit's time and "
              f"{MEMORY_TARGET:g}x its peak memory: time {'met' if t20 <= TIME_TARGET else 'NOT met'} ({t20:.2f}x), "
              f"memory {'met' if m20 <= MEMORY_TARGET else 'NOT met'} ({m20:.2f}x).")
    return "\n".join(md)


def _difference(n: int, base: dict, ours: dict) -> str:
    """The outputs whose terms differ from the baseline's, and the held-out errors of both models."""
    lines = [f"{n:,} rows: terms differ from the baseline's (family {base['family']} -> {ours['family']}):"]
    for o, terms in ours["terms"].items():
        b = base["terms"].get(o, [])
        if b != terms:
            lines.append(f"- {o}: only baseline {', '.join(sorted(set(b) - set(terms))) or '-'}; only ours "
                         f"{', '.join(sorted(set(terms) - set(b))) or '-'}")
    for prec in ("double", "float"):
        for o in ours["terms"]:
            a, b = base["held_out"].get(prec, {}).get(o), ours["held_out"].get(prec, {}).get(o)
            if a and b and "max" in a:
                lines.append(f"- held out, {prec} {o}: max {a['max']:.4g} -> {b['max']:.4g}, noisy RMS "
                             f"{a['noisy_rms']:.4g} -> {b['noisy_rms']:.4g}, rounding's share "
                             f"{100 * a['share']:.1f} % -> {100 * b['share']:.1f} %")
    return "\n".join(lines)


def main() -> None:
    ap = parser(__doc__)
    alone = ap.add_mutually_exclusive_group()
    alone.add_argument("--rows-only", action="store_true", help="part 3 alone (rows without limit)")
    alone.add_argument("--command-only", action="store_true", help="part 4 alone (the fit command)")
    ap.add_argument("--baseline", metavar="DIR",
                    help="part 4 also runs both commands with the fitgen source tree at DIR and compares its terms")
    args = ap.parse_args()
    baseline = os.path.abspath(args.baseline) if args.baseline else None
    if args.rows_only:
        print(part_rows_without_limit())
        return
    if args.command_only:
        print(part_command(baseline))
        return
    need_tools("Rscript")  # part 1 compares with R's step()
    load0 = os.getloadavg()
    head = ["# fitgen fit benchmark", "",
            f"python {platform.python_version()}, numpy {np.__version__}, scipy {scipy.__version__}, "
            f"BLAS: {blas_info()} (fitgen's compress/search/refit limit themselves to 1 thread); "
            f"{r_version()} (reference BLAS); {os.cpu_count()} CPUs; "
            f"load average at start {load0[0]:.2f}", ""]
    p1, _ = part_paper_grid()
    p2 = part_rows() + "\n\n" + part_rows_without_limit() + "\n\n" + part_command(baseline)
    load1 = os.getloadavg()
    total = time.perf_counter() - T_START
    tail = f"Total benchmark time {total:.0f} s; load average at end {load1[0]:.2f} (1 min), {load1[1]:.2f} (5 min)."
    print("\n".join(head) + "\n" + p1 + "\n\n" + p2 + "\n\n" + tail)
    log("done")


if __name__ == "__main__":
    main()
