"""The trade-off sweep's report (fitgen.c.tradeoff): a CSV of every point, a Markdown page with the
recommendation and the Pareto front, and the plot."""

from __future__ import annotations

import csv
import io
from pathlib import Path

from fitgen.base.errors import InputError
from fitgen.c.tradeoff import OP_KINDS, Point, TradeoffResult
from fitgen.c.tradeoff_choice import ACCURACY_TIE
from fitgen.physics.pose import POSE_NAMES, POSE_UNITS


def _g(x, digits: int = 3) -> str:
    return "" if x is None else f"{x:.{digits}g}"


def _k(k) -> str:
    return k if isinstance(k, str) else f"{k:g}"


def cost_name(result: TradeoffResult) -> str:
    """What the costs count: "instructions", or "cycles on uno"."""
    return f"cycles on {result.core}" if result.core else "instructions"


def to_csv(result: TradeoffResult) -> str:
    outs = result.scene.outputs
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["point", "k", "max_terms", "family", "refine", "precision", "style", "terms"]
               + [f"terms_{o}" for o in outs] + [f"ops_{k}" for k in OP_KINDS]
               + ["instructions", "loop_instructions", "flash", "object_flash", "cycles"]
               + [f"{o}_{s}" for o in outs for s in ("max", "rms", "noisy_max", "noisy_rms")]
               + [f"{o}_share" for o in outs] + ["score", "share", "front", "recommended", "model", "note"])
    for i, p in enumerate(result.points):
        kn = p.knobs
        w.writerow([i + 1, _k(kn.k), kn.max_terms or "", kn.family, kn.refine, kn.precision, kn.style, p.terms]
                   + [p.terms_per_output.get(o, "") for o in outs] + [p.ops.get(k, "") for k in OP_KINDS]
                   + [_g(p.instructions, 6), _g(p.loop_instructions, 6), _g(p.flash, 9), _g(p.object_flash, 9),
                      _g(p.cycles, 7)]
                   + [_g(p.errors[o][s], 6) if p.errors else "" for o in outs
                      for s in ("max", "rms", "noisy_max", "noisy_rms")]
                   + [_g(p.errors[o]["share"], 6) if p.errors else "" for o in outs]
                   + [_g(p.score, 6), _g(p.share, 6), int(i in result.front), int(i == result.recommended),
                      p.model_hash[:12], p.note])
    return buf.getvalue()


def _row(i: int, p: Point, result: TradeoffResult) -> str:
    kn = p.knobs
    mark = ("**rec** " if i == result.recommended else "") + ("front" if i in result.front else "")
    ops = "/".join(str(p.ops.get(k, 0)) for k in OP_KINDS) if p.ops else ""
    errs = " | ".join(f"{_g(p.errors[o]['rms'])} / {_g(p.errors[o]['noisy_rms'])} / {_g(p.errors[o]['noisy_max'])}"
                      if p.errors else "" for o in result.scene.outputs)
    return (f"| {i + 1} | {_k(kn.k)} | {kn.max_terms or '-'} | {kn.method} | {kn.precision} | {kn.style} | {p.terms} | "
            f"{ops} | {_g(p.instructions, 4)} | " + (f"{_g(p.cycles, 5)} | " if result.core else "")
            + f"{_g(p.flash, 6)} | {errs} | {_g(p.score)} | "
            f"{'' if p.share is None else f'{p.share:.1%}'} | {mark.strip()} |"
            + (f" {p.note}" if p.note else ""))


def describe(i: int | None, result: TradeoffResult) -> str:
    if i is None:
        return "none"
    p = result.points[i]
    cost = f"{_g(p.cycles, 5)} cycles per estimate on {result.core}" if result.core else \
        f"{_g(p.instructions, 4)} instructions per estimate"
    return f"point {i + 1} ({p.knobs.label}): {p.terms} terms, {cost}, {_g(p.flash, 6) or '?'} bytes of flash, " \
           f"score {_g(p.score)}"


def reproduce(i: int, result: TradeoffResult) -> list[str]:
    """The fitgen commands that give point ``i``'s model and C: the scene's grid simulated, fitted as the sweep fits
    it (the sensor's noise, float rounding; --force where the sensor cannot resolve the scene), then generated."""
    from shlex import quote

    kn = result.points[i].knobs
    spec = result.scene_given or result.scene.name  # a scene file by its path: simulate reads it again
    data = quote(f"{Path(spec).stem if Path(spec).suffix else spec}.csv")
    k = kn.k if isinstance(kn.k, str) else f"{kn.k:g}"
    fit = (f"fitgen fit {data} --k {k}" + (f" --max-terms {kn.max_terms}" if kn.max_terms else "")
           + f" --family {kn.family}" + (f" --refine {kn.refine}" if kn.refine else "")
           + (" --force" if result.warnings else "") + " -o model.json")
    gen = (f"fitgen codegen model.json --precision {kn.precision}"
           + (f" --style {kn.style}" if kn.precision != "fixed" else "")
           + (f" --target {result.core}" if result.core else "") + " -o c")
    return [f"fitgen simulate --sensor {' '.join(quote(x) for x in result.given or (result.sensor,))} "
            f"--scene {quote(spec)} -o {data}", fit, gen]


def to_markdown(result: TradeoffResult, plot: str | None = None) -> str:
    s, outs = result.setup, result.scene.outputs
    units = {o: POSE_UNITS[POSE_NAMES.index(o)] for o in outs}
    lines = [f"# Trade-off: sensor {result.sensor} ({result.transfer}), scene {result.scene.name}", ""]
    raised = (f", raised from the scene's {result.scene.levels} for the rows the fit's first equation needs"
              if s["levels"] != result.scene.levels else "")
    lines.append(f"Training: the scene's grid, {s['training_rows']:,} poses ({s['levels']} levels per moving "
                 f"component{raised}), simulated noise-free and fitted for the sensor's noise and float rounding. "
                 f"Held-out: {s['held_out']:,} random poses in the scene's box (seed "
                 f"{s['seed']}), noise-free and with the sensor's noise ({s['noise']:g} {s['units']} rms per element, "
                 f"{s['noise_draws']} draws). {s['fits']} fits, {s['measured']} distinct builds measured.")
    lines.append("")
    lines.append("Target (RMS error with noise): " + ", ".join(f"{o} {result.target[o]:g} {units[o]}" for o in outs)
                 + ". Score = the worst output's RMS error with noise / its target; <= 1 meets the target.")
    lines.append("")
    if result.warnings:
        lines.append(f"Resolvability: sensor {result.sensor} cannot resolve everything scene {result.scene.name} asks "
                     "for (fitted anyway, as with `fit --force`):")
        lines += [f"- {w}" for w in result.warnings]
        lines.append("")
    for n in result.notes:
        lines.append(f"Note: {n}.")
        lines.append("")
    if result.over_share:
        lines.append(f"**Rounding check failed** on {len(result.over_share)} point(s): the generated C deviates from "
                     f"the double model by more than {100 * result.max_share:.3g} % of that model's held-out max error "
                     "(they are left off the front and the recommendation): points "
                     + ", ".join(str(i + 1) for i in result.over_share) + ".")
        lines.append("")
    if result.constant:
        lines.append(f"**No better than a constant** at {len(result.constant)} point(s): an output whose equation has "
                     "no terms, or whose RMS error with noise is no less than its spread over the held-out poses "
                     "(the constant at its mean does as well), is not estimated, whatever its score (they are left "
                     "off the front and the recommendation): points "
                     + ", ".join(str(i + 1) for i in result.constant) + ".")
        lines.append("")
    lines.append("## Recommendation")
    lines.append("")
    if result.recommended is None:
        lines.append("No point could be measured." if not (result.over_share or result.constant) else
                     "No point left: every measured point failed the rounding check or estimates an output no "
                     "better than a constant (above).")
    elif result.met:
        lines.append(f"Meets the target with the fewest {cost_name(result)}: {describe(result.recommended, result)}.")
    else:
        lines.append(f"No point meets the target. The most accurate (scores within {ACCURACY_TIE:.0%} of the best "
                     f"taken as equal, then the fewest {cost_name(result)}): {describe(result.recommended, result)}.")
    if result.recommended is not None:
        lines += ["", "Its model and C:", ""] + [f"    {c}" for c in reproduce(result.recommended, result)]
    lines.append("")
    lines.append(f"## Pareto front ({cost_name(result)} per estimate against score)")
    lines.append("")
    shown = set()
    for i in result.front:
        p = result.points[i]
        if (p.model_hash, p.knobs.precision, p.knobs.style) in shown:
            continue
        shown.add((p.model_hash, p.knobs.precision, p.knobs.style))
        same = [j + 1 for j in result.front if j != i and result.points[j].model_hash == p.model_hash
                and (result.points[j].knobs.precision, result.points[j].knobs.style) == (p.knobs.precision, p.knobs.style)]
        lines.append(f"- {describe(i, result)}" + (f" (the same build: points {', '.join(map(str, same))})"
                                                    if same else ""))
    lines.append("")
    if plot:
        lines.append(f"![{cost_name(result)} against score]({plot})")
        lines.append("")
    lines.append("## All points")
    lines.append("")
    flash = ("the AVR program (avr-gcc -O2, the estimator with a loop over its inputs) less its inputs, "
             f"library code included; cycles: per estimate on {result.core} in simavr" if result.core else
             "bytes the estimator adds to a linked Cortex-M4F (double, float) or Cortex-M0 (fixed) program, library "
             "code included")
    lines.append("Ops: mul/add/div/sqrt/cbrt per estimate as the templates write them. Instructions: x86-64, inside "
                 f"tm_estimate, per estimate (callgrind). Flash: {flash}. Errors per output: RMS "
                 "noise-free / RMS with noise / max with noise. Rounding's share: the largest deviation of this "
                 "precision's C from the double model on the noise-free held-out readings, over the double model's "
                 "max error there (worst output).")
    lines.append("")
    lines.append("| # | k | cap | family | precision | style | terms | ops | instructions | "
                 + ("cycles | " if result.core else "") + "flash | "
                 + " | ".join(f"{o} [{units[o]}]" for o in outs) + " | score | rounding's share | |")
    lines.append("|" + " --- |" * (14 + len(outs) - 1 + bool(result.core)))
    lines += [_row(i, p, result) for i, p in enumerate(result.points)]
    return "\n".join(lines) + "\n"


def write_outputs(result: TradeoffResult, folder: str | Path) -> tuple[list[Path], str]:
    """DIR/tradeoff.csv, DIR/tradeoff.md and (matplotlib permitting) DIR/tradeoff.png, written together (a Ctrl-C
    between two left a new table beside the last run's page and plot); returns the paths and the markdown."""
    from fitgen.base.fileio import write_all
    from fitgen.base.signals import signals_held

    folder, png = Path(folder), None
    try:
        from fitgen.app import plots

        png = plots.tradeoff_png(result)
    except InputError as exc:
        result.notes.append(f"no plot: {exc}")
    text = to_markdown(result, None if png is None else "tradeoff.png")
    files = [(folder / "tradeoff.csv", to_csv(result)), (folder / "tradeoff.md", text)]
    with signals_held():
        paths = write_all(files + ([(folder / "tradeoff.png", png)] if png is not None else []))
        if png is None:
            (folder / "tradeoff.png").unlink(missing_ok=True)  # an earlier run's plot would pass for this run's
    return paths, text
