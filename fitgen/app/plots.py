"""Figures (matplotlib, an optional extra): estimate against target, as the paper's Figures 4-7."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fitgen.physics.dataset import Dataset
from fitgen.base.errors import InputError
from fitgen.base.fileio import write_in_folder
from fitgen.equations.model import Model


def _plt():
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise InputError("plots need matplotlib: pip install 'magtactile-fitgen[plots]'") from None
    return plt


def require(folder) -> Path:
    """What a figure needs, checked before any work rather than after it: matplotlib, and ``folder`` that can be
    made. The folder is made when the figures are written, so a command refused on its input leaves none."""
    from fitgen.base.fileio import check_folder

    _plt()
    return check_folder(folder, "--plot")


def _png(fig) -> bytes:
    """``fig`` as PNG bytes (no date in them: the same figure gives the same bytes); the figure is closed."""
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, metadata={"Software": None})
    _plt().close(fig)
    return buf.getvalue()


def _estimates(model: Model, ds: Dataset):
    """(file name, PNG) of each output of ``model`` that ``ds`` has a column of: target and estimate against the
    row index (rows sorted by target), the error below."""
    plt = _plt()
    pred = model.predict(ds.inputs)
    for j, eq in enumerate(model.equations):
        if eq.name not in ds.target_names:
            continue
        y = ds.target(eq.name)
        order = np.argsort(y, kind="stable")
        fig, (a, b) = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
        a.plot(pred[order, j], ".", ms=2, label="estimate")
        a.plot(y[order], "-", lw=1.2, color="k", label="target")
        a.set_ylabel(f"{eq.name} [{eq.unit}]")
        a.legend(loc="upper left")
        err = pred[:, j] - y
        a.set_title(f"{eq.name}: {len(eq.terms)} terms (the model in double), on {len(y)} rows: max error "
                    f"{np.max(np.abs(err)):.3g} {eq.unit}, RMS {np.sqrt(np.mean(err * err)):.3g} {eq.unit}",
                    fontsize=10)
        b.plot(err[order], ".", ms=2)
        b.set_ylabel(f"error [{eq.unit}]")
        b.set_xlabel("data index (sorted by target)")
        fig.tight_layout()
        yield f"estimate_{eq.name}.png", _png(fig)


def estimate_vs_target(model: Model, ds: Dataset, folder: Path) -> list[Path]:
    """One PNG per output: target and estimate against the row index (rows sorted by target)."""
    return [write_in_folder(folder, name, png) for name, png in _estimates(model, ds)]


def _sweep_png(model: Model, sweep_inputs: np.ndarray, sweep_values: np.ndarray, output: str, on: str = "") -> bytes:
    plt = _plt()
    j = model.output_names.index(output)
    unit = model.equation(output).unit
    est = model.predict(sweep_inputs)[:, j]
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(sweep_values, est, ".", ms=3, label="estimate")
    ax.plot(sweep_values, sweep_values, "-", color="k", lw=1, label="target")
    ax.set_xlabel(f"target {output} [{unit}]")
    ax.set_ylabel(f"estimated {output} [{unit}]")
    ax.legend()
    ax.set_title(f"{output} in steps of {sweep_values[1] - sweep_values[0]:.2g} {unit}, other components 0"
                 + (f" ({on})" if on else ""), fontsize=10)
    fig.tight_layout()
    return _png(fig)


def resolution_sweep(model: Model, sweep_inputs: np.ndarray, sweep_values: np.ndarray, output: str,
                     folder: Path) -> Path:
    """The paper's Figure 7: one component stepped 0.1 deg at a time, the others at 0."""
    return write_in_folder(folder, f"sweep_{output}.png", _sweep_png(model, sweep_inputs, sweep_values, output))


def _rotations(model: Model) -> list[str]:
    from fitgen.physics.pose import POSE_NAMES

    return [name for name in POSE_NAMES[3:] if name in model.output_names]


def _sweeps(model: Model, sensor):
    """(file name, PNG) of :func:`resolution_sweep` of each rotation the model estimates, -5 to 5 deg on
    ``sensor``."""
    from fitgen.physics.pose import POSE_NAMES
    from fitgen.physics.simulate import simulate

    for name in _rotations(model):
        values = np.round(np.arange(-5.0, 5.0 + 1e-9, 0.1), 10)
        poses = np.zeros((len(values), 5))
        poses[:, POSE_NAMES.index(name)] = values
        yield f"sweep_{name}.png", _sweep_png(model, simulate(sensor, poses).inputs, values, name,
                                              f"sensor {sensor.name}, noise-free")


def rotation_sweeps(model: Model, sensor, folder: Path) -> list[Path]:
    """:func:`resolution_sweep` of each rotation the model estimates, -5 to 5 deg on ``sensor``."""
    return [write_in_folder(folder, name, png) for name, png in _sweeps(model, sensor)]


def report_figures(model: Model, ds: Dataset, sensor=None) -> dict[str, bytes]:
    """fitgen report --plot's figures, file name -> PNG, drawn but not written (the command writes them with its
    other outputs): :func:`estimate_vs_target`'s, and with ``sensor`` :func:`rotation_sweeps`'s. Seconds of work:
    a bar on a terminal moves through them."""
    import itertools

    from fitgen.base.progress import Progress

    names = [f"estimate_{eq.name}.png" for eq in model.equations if eq.name in ds.target_names]
    names += [f"sweep_{name}.png" for name in _rotations(model)] if sensor is not None else []
    drawn = itertools.chain(_estimates(model, ds), _sweeps(model, sensor) if sensor is not None else ())
    out = {}
    with Progress("plots", len(names)) as bar:
        for name in names:
            bar.update(1, f"drawing {name}")  # before: the first figure is as slow as the others
            name, png = next(drawn)  # drawn here, as it is asked for
            out[name] = png
    return out


def _plain_log_ticks(axis, values) -> None:
    """Log ``axis`` labelled in plain numbers (0.3, not 3 x 10^-1), ``values`` its data: within a decade every minor
    tick labelled, 1.5 and 2.5 too (124-420 instructions had labels at 200, 300 and 400 alone, the cheapest points'
    third of the axis none), else 1-2-3-5 (or they overlap)."""
    from matplotlib.ticker import FuncFormatter, LogLocator

    within = max(values) < 10 * min(values)
    digits = "123456789" if within else "1235"
    if within:
        axis.set_minor_locator(LogLocator(subs=(1.5, 2, 2.5, 3, 4, 5, 6, 7, 8, 9)))
    axis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g}"))
    # by the leading digit (0.3's is 3, not its "0"): values below 1 are read off too
    axis.set_minor_formatter(FuncFormatter(lambda x, _: f"{x:g}" if f"{x:.0e}"[0] in digits else ""))


def tradeoff_png(result) -> bytes:
    """fitgen tradeoff: instructions (or a core's cycles) per estimate against score (log axes), the front
    joined, the target (score 1) dashed, the recommended point ringed; colour by precision, marker by family."""
    plt = _plt()
    colours = {"double": "tab:blue", "float": "tab:orange", "fixed": "tab:green"}
    markers = {"all": "o", "no-roots": "s", "integer": "^", "harmonics": "D"}
    refined = "P"  # any family with refinement steps
    fig, ax = plt.subplots(figsize=(9.5, 4.8))
    pts = [(i, p) for i, p in enumerate(result.points) if result.cost(p) is not None and p.score is not None]
    # left out of the front and the recommendation (no better than a constant, rounding past --max-share): grey,
    # so that the front is seen to be over the points it is over
    out = set(result.constant) | set(result.over_share)
    seen = set()
    for i, p in pts:
        key = ("left out",) if i in out else (p.knobs.precision, p.knobs.method)
        colour = "0.6" if i in out else colours[p.knobs.precision]
        face = "none" if p.knobs.style == "table" or i in out else colour
        ax.scatter(result.cost(p), p.score, s=36, marker=refined if p.knobs.refine else markers[p.knobs.family],
                   facecolors=face, edgecolors=colour, linewidths=1, alpha=0.85,
                   label=None if key in seen else "left out (a constant; --max-share)"
                   if i in out else f"{p.knobs.precision}, {p.knobs.method}")
        seen.add(key)
    front = [result.points[i] for i in result.front]
    if front:
        ax.plot([result.cost(p) for p in front], [p.score for p in front], "-", color="k", lw=1, label="Pareto front")
    if result.recommended is not None:
        r = result.points[result.recommended]
        ax.scatter(result.cost(r), r.score, s=220, facecolors="none", edgecolors="red", linewidths=1.6,
                   label="recommended" if result.met else "most accurate (target not met)")
    ax.axhline(1.0, color="red", ls="--", lw=0.8, label="target (score 1; below: met)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    scores = [p.score for _, p in pts] + [1.0]  # the target's line is on the axis too
    costs = [result.cost(p) for _, p in pts] or [1.0]  # no points: an empty plot, labelled as any other
    _plain_log_ticks(ax.xaxis, costs)
    _plain_log_ticks(ax.yaxis, scores)
    ax.set_xlabel(f"cycles per estimate on {result.core} (simavr)" if result.core
                  else "x86-64 instructions per estimate (callgrind)")
    ax.set_ylabel("score: worst RMS error with noise / target")
    ax.set_title(f"sensor {result.sensor}, scene {result.scene.name} (hollow: table style)", fontsize=10)
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))  # beside the points, never over them
    fig.tight_layout()
    return _png(fig)


def identification(ident, path: Path, truth: dict | None = None) -> Path:
    """fitgen identify --plot: :func:`identification_png` written to ``path``."""
    return write_in_folder(path.parent, path.name, identification_png(ident, truth))


def identification_png(ident, truth: dict | None = None) -> bytes:
    """Each reading's standardized residual by row (rows off the skin shaded), and what the capture determines
    (each element's sensitivity, the magnet's offset from the elements' centre) with its standard error beside
    the prior's spread about the drawing, as PNG; ``truth`` (a simulated unit's, by the names of
    ``ident.derived()``): marked beside them."""
    from fitgen.physics.pose import off_skin

    plt = _plt()
    r = ident.standardized_residuals
    n, N = r.shape
    post = ident.derived()
    prior = ident.derived(np.diag(ident.space.prior_sd ** 2), np.zeros(ident.space.size))
    fig, (a, b, c) = plt.subplots(1, 3, figsize=(13, 4.8), gridspec_kw={"width_ratios": [2.4, 1.6, 1]})
    rows = np.arange(1, n + 1)
    for i in np.nonzero(off_skin(ident.problem.poses))[0]:
        a.axvspan(i + 0.5, i + 1.5, color="0.9", lw=0)
    for k in range(N):
        a.plot(rows, r[:, k], ".", ms=4, label=f"e{k + 1}")
    for y in (-3, 3):
        a.axhline(y, color="k", ls="--", lw=0.7)
    a.set_xlabel("row of the capture (grey: off the skin)")
    a.set_ylabel("residual / its standard deviation")
    a.set_title(f"residuals: reduced chi-square {ident.reduced_chi2:.2f}", fontsize=10)
    # the legends below the panels: inside, they covered the corner where a row standing out past 3 is drawn
    a.legend(fontsize=7, ncol=N, loc="upper center", bbox_to_anchor=(0.5, -0.14), handletextpad=0.1, markerscale=2)

    def panel(ax, names, labels, title, unit):
        x = np.arange(len(names))
        ax.errorbar(x - 0.12, [prior[k][0] for k in names], [prior[k][1] for k in names], fmt="none", ecolor="0.6",
                    elinewidth=6, alpha=0.6, label="prior: the drawing, 1 sd")
        ax.errorbar(x + 0.12, [post[k][0] for k in names], [post[k][1] for k in names], fmt="o", color="k", ms=4,
                    capsize=3, label="identified, 1 standard error")
        if truth:
            ax.plot(x + 0.12, [truth[k] for k in names], "x", color="tab:red", ms=7, mew=1.5,
                    label="the unit's truth (simulated)")
        ax.set_xticks(x, labels)
        ax.set_ylabel(unit)
        ax.set_title(title, fontsize=10)
        ax.grid(True, axis="y", lw=0.3, alpha=0.5)

    sens = [k for k in post if "sensitivity" in k]
    offs = [k for k in post if "offset" in k]
    panel(b, sens, [k.split()[0] for k in sens], "element sensitivity (gain x polarisation)",
          "sensitivity [x the drawing's]")
    b.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.08))
    panel(c, offs, [k.split()[-2] for k in offs], "magnet offset from the elements'\ncentre, in their own frame",
          "offset [mm]")
    fig.tight_layout()
    return _png(fig)


def allan_png(av) -> bytes:
    """tactile-host noise --plot: each element's overlapping Allan deviation against the row's reading time, beside
    white noise's (the one-sample deviation over sqrt(S)), the candidates marked, as PNG."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    t = av.curve_m / av.rate
    for k in range(av.curve.shape[1]):
        line, = ax.loglog(t, 1e3 * av.curve[:, k], lw=1, label=f"e{k + 1}")
        ax.loglog(t, 1e3 * av.single[k] / np.sqrt(av.curve_m), ls=":", lw=0.8, color=line.get_color())
    for s, r in zip(av.candidates, av.worst):
        ax.axvline(s / av.rate, color="0.7", lw=0.6)
        ax.annotate(f"{s}: {r:.2f}x", (s / av.rate, ax.get_ylim()[1]), fontsize=7, rotation=90, va="top", ha="right")
    ax.set_xlabel("reading time of a row [s] (samples per row / sample rate)")
    ax.set_ylabel("Allan deviation [mV]")
    _plain_log_ticks(ax.xaxis, t)
    _plain_log_ticks(ax.yaxis, [v for line in ax.get_lines() for v in line.get_ydata()])
    # on two lines: on one, the figure's edge cut it
    ax.set_title(f"rest noise, {av.samples} samples at {av.rate:.0f}/s: solid measured, dotted white noise;\n"
                 "lines at the candidate samples per row, each with its worst element's real / recorded noise",
                 fontsize=9)
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    ax.legend(fontsize=7, ncol=4, loc="lower left")
    fig.tight_layout()
    return _png(fig)


def check_png(result, units: dict) -> bytes:
    """fitgen check --plot: per output, the measured max and RMS error on the check capture beside the figures
    drawn from the prediction (one per unit and draw), as PNG; ``units``: each output's unit."""
    plt = _plt()
    fig, axes = plt.subplots(1, len(result.outputs), figsize=(2.3 * len(result.outputs) + 1, 3.6), squeeze=False)
    jitter = np.random.default_rng(0).uniform(-0.12, 0.12, len(next(iter(result.drawn.values()))["max"]))
    failed = result.failed()
    for ax, o in zip(axes[0], result.outputs):
        for x, figure in enumerate(("max", "rms")):
            ax.plot(x + jitter, result.drawn[o][figure], ".", color="0.6", ms=4,
                    label="predicted (a draw of the stage's error and the noise on each unit)" if x == 0 else None)
            # a cross where it failed, not the colour alone: red and green read alike to many
            marker, colour, size, said = ("X", "C3", 9, "beyond the prediction") if o in failed else \
                ("D", "C2", 7, "as predicted")
            ax.plot([x], [result.measured[o][figure]], marker, color=colour, ms=size,
                    label=None if x else f"measured on the unit: {said}")
        ax.set_xticks([0, 1], ["max", "RMS"])
        ax.set_xlim(-0.5, 1.5)
        ax.set_yscale("log")
        _plain_log_ticks(ax.yaxis, [v for line in ax.get_lines() for v in line.get_ydata()])
        ax.set_title(f"{o} [{units[o]}]", fontsize=10)
        ax.grid(True, axis="y", which="both", lw=0.3, alpha=0.5)
    axes[0][0].set_ylabel("|estimate - stage label|")
    legend = {}  # every output's entries, once: the first output's alone missed a cross or a diamond
    for ax in axes[0]:
        legend.update((label, h) for h, label in zip(*ax.get_legend_handles_labels()) if label not in legend)
    fig.legend(list(legend.values()), list(legend), loc="lower center", ncol=min(len(legend), 3), fontsize=8)
    fig.suptitle(f"check: {result.rows} rows; a red cross: beyond every prediction by more than the check allows",
                 fontsize=9)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    return _png(fig)
