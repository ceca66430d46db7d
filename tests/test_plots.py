"""fitgen.app.plots as a reader sees the figures: each axis's quantity with its unit, titles that say what is shown
and on what, and no text cut off at the figure's edge. The figures are read as matplotlib draws them (``_png``
replaced by a recorder), not as pixels."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from fitgen.app import plots  # noqa: E402


@pytest.fixture
def figures(monkeypatch):
    """The figures plots draws, in order, instead of their PNG bytes."""
    drawn = []
    monkeypatch.setattr(plots, "_png", lambda fig: drawn.append(fig) or b"")
    return drawn


def _texts(fig) -> list[str]:
    """Every axis label and title of ``fig`` (suptitle included)."""
    out = [fig._suptitle.get_text()] if fig._suptitle is not None else []
    for ax in fig.axes:
        out += [ax.get_xlabel(), ax.get_ylabel(), ax.get_title()]
    return out


def _model_and_data():
    """A small fitted model of the paper drawing (gmr) and noise-free rows of it."""
    from fitgen.fitting.fit import FitSettings, fit_model
    from fitgen.physics.sensor import load_sensor
    from fitgen.physics.simulate import DEFAULT_RANGES, pose_rng, random_poses, simulate

    sensor = load_sensor("paper").with_transfer("gmr")
    train = simulate(sensor, random_poses(400, DEFAULT_RANGES, pose_rng(3)))
    model = fit_model(train, ("dz", "thx"), FitSettings.family("integer"))
    return sensor, model, simulate(sensor, random_poses(50, DEFAULT_RANGES, pose_rng(4)))


def test_the_estimate_and_sweep_figures_give_every_axis_its_unit_and_say_what_they_were_drawn_on(figures):
    """The error panel read "error" with no unit (mm or deg: which the reader had to guess), the sweep's axes
    "target thx" and "estimated thx" and its title "steps of 0.1" with none either, and neither figure said on what
    it was drawn: how many rows, the sweep's sensor and that it is noise-free."""
    sensor, model, ds = _model_and_data()
    plots.report_figures(model, ds, sensor)
    est_dz, est_thx, sweep = figures
    assert est_dz.axes[1].get_ylabel() == "error [mm]" and est_thx.axes[1].get_ylabel() == "error [deg]"
    title = est_dz.axes[0].get_title()
    err = model.predict(ds.inputs)[:, 0] - ds.target("dz")
    assert "on 50 rows" in title and f"RMS {np.sqrt(np.mean(err * err)):.3g} mm" in title
    assert f"max error {np.max(np.abs(err)):.3g} mm" in title  # the figure the report prints
    ax = sweep.axes[0]
    assert ax.get_xlabel() == "target thx [deg]" and ax.get_ylabel() == "estimated thx [deg]"
    assert "steps of 0.1 deg" in ax.get_title() and "sensor paper, noise-free" in ax.get_title()


def _inside(fig, artist) -> bool:
    """``artist`` drawn within ``fig``'s canvas, not cut off at its edge."""
    fig.canvas.draw()
    box, edge = artist.get_window_extent(fig.canvas.get_renderer()), fig.bbox
    return edge.x0 <= box.x0 and box.x1 <= edge.x1 and edge.y0 <= box.y0 and box.y1 <= edge.y1


def _tick_texts(fig, axis) -> set[str]:
    fig.canvas.draw()
    ticks = getattr(fig.axes[0], axis)
    return {t.get_text() for t in ticks.get_ticklabels(minor=True)} | {t.get_text() for t in ticks.get_ticklabels()}


def test_the_allan_figure_has_its_whole_title_and_plain_tick_labels(figures):
    """tactile-host noise --plot: the title ran past the figure's right edge ("...the worst element's ratio" cut
    off), and the deviation's ticks read 4 x 10^-1 where 0.4 mV is meant."""
    from host.allan import averaging

    x = np.random.default_rng(0).normal(0.0, 5e-4, (3000, 8))
    plots.allan_png(averaging(x, 100.0))
    fig = figures[0]
    assert _inside(fig, fig.axes[0].title)
    shown = _tick_texts(fig, "yaxis") | _tick_texts(fig, "xaxis")
    assert not any("times" in t or "^" in t for t in shown) and {"0.1", "1"} <= shown, shown


def test_the_tradeoff_plot_labels_the_cheap_end_of_an_axis_within_a_decade_and_names_the_target(figures):
    """The press scene's points cost 124-420 instructions: the axis was labelled at 200, 300 and 400 only, so the
    recommended point's cost (124) and its neighbours' had no label within a third of the axis; the target's red
    dashed line was in no legend."""
    from types import SimpleNamespace

    knobs = SimpleNamespace(precision="float", method="equations", style="unrolled", refine=0, family="integer")
    points = [SimpleNamespace(knobs=knobs, score=s, instructions=c)
              for s, c in ((0.0156, 124), (0.0114, 133), (0.0098, 420))]
    result = SimpleNamespace(points=points, front=[0, 1], recommended=0, met=True, constant=[], over_share=[],
                             core=None, sensor="paper", scene=SimpleNamespace(name="press"),
                             cost=lambda p: p.instructions)
    plots.tradeoff_png(result)
    fig = figures[0]
    fig.canvas.draw()
    ax = fig.axes[0]
    labelled = [float(t.get_text()) for t in ax.xaxis.get_ticklabels(minor=True) + ax.xaxis.get_ticklabels()
                if t.get_text() and ax.get_xlim()[0] <= float(t.get_text()) <= ax.get_xlim()[1]]
    assert min(labelled) <= 150 and {200, 300, 400} <= set(labelled), labelled
    # and the red dashed line is named: the target
    assert "target (score 1; below: met)" in [t.get_text() for t in ax.get_legend().get_texts()]


def test_the_check_figure_tells_a_failed_output_by_its_marker_and_names_both_in_the_legend(figures):
    """fitgen check --plot: a failed output's measured figures were red diamonds and a passed one's green ones, the
    same marker (red and green read alike to many readers, and alike in greyscale), and the legend, taken from the
    first output alone, showed one of the two."""
    from types import SimpleNamespace

    drawn = {"max": np.full(8, 0.02), "rms": np.full(8, 0.01)}
    result = SimpleNamespace(outputs=["dx", "dz"], rows=30, drawn={"dx": drawn, "dz": drawn},
                             measured={"dx": {"max": 0.021, "rms": 0.011}, "dz": {"max": 0.5, "rms": 0.3}},
                             failed=lambda: ["dz"])
    plots.check_png(result, {"dx": "mm", "dz": "mm"})
    fig = figures[0]
    markers = [[line.get_marker() for line in ax.get_lines()][1::2] for ax in fig.axes]
    assert markers[0] == ["D", "D"] and markers[1] == ["X", "X"]
    said = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "measured on the unit: as predicted" in said and "measured on the unit: beyond the prediction" in said


def _fake_identification(worst: float):
    """What identification_png reads of an identification: 40 rows of 8 elements, the first 3 off the skin, the
    largest residual ``worst`` at row 35, element 8."""
    from types import SimpleNamespace

    r = np.random.default_rng(1).normal(0.0, 0.7, (40, 8))
    r[34, 7] = worst
    poses = np.zeros((40, 5))
    poses[3:, 2] = -0.5
    poses[:3, 2] = 0.2
    names = [f"magnet offset from the elements' centre {a} [mm]" for a in "xyz"]
    names += [f"e{k} sensitivity [x drawing]" for k in range(1, 9)]

    def derived(cov=None, theta=None):
        return {n: (0.0 if "offset" in n else 1.0, 0.2 if cov is not None else 0.01) for n in names}

    return SimpleNamespace(standardized_residuals=r, reduced_chi2=1.0, derived=derived,
                           space=SimpleNamespace(prior_sd=np.ones(11), size=11), problem=SimpleNamespace(poses=poses))


def test_the_identify_figure_keeps_its_legends_off_the_data_and_says_the_offsets_frame(figures):
    """fitgen identify --plot: the residuals' legend sat in the upper right corner, over the line at 3 where a row
    standing out is drawn (one at 3.2 near the end of the capture hid behind it), and the sensitivities' legend over
    the prior's bars; the offset panel did not say the frame its offsets are in (the elements' own, since identify
    reads them there) nor the sensitivity axis its unit."""
    plots.identification_png(_fake_identification(3.2))
    fig = figures[0]
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    a, b, c = fig.axes
    for ax in (a, b):
        legend, area = ax.get_legend().get_window_extent(renderer), ax.get_window_extent(renderer)
        assert not legend.overlaps(area), ax.get_title()
    assert "own frame" in c.get_title() and c.get_ylabel() == "offset [mm]"
    assert b.get_ylabel() == "sensitivity [x the drawing's]"
    assert _inside(fig, a.get_legend()) and _inside(fig, b.get_legend())


def test_bench_layout_search_draws_its_figure(tmp_path):
    """bench/layout_search.py --plot (docs/layouts.md's figure) imported plots._save, which a refactor had
    removed: the run ended in an ImportError after its table, and the committed figure could not be drawn again."""
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run([sys.executable, str(root / "bench" / "layout_search.py"), "--no-search", "--plot",
                           str(tmp_path)], capture_output=True, text=True, cwd=root, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "layouts-tilt-floor.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bench_estimators_front_keeps_its_legend_off_the_points_and_its_ticks_plain(tmp_path, monkeypatch):
    """bench/estimators.py --plot (docs/estimators.md's figure): each panel's legend sat in its upper right corner,
    over the costliest points and their labels (MLP 64-64 on `paper`), and the tilt panel's ticks read 6 x 10^0."""
    from pathlib import Path
    from types import SimpleNamespace

    import matplotlib.figure

    pytest.importorskip("sklearn")
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1] / "bench"))
    import estimators

    drawn = []
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", lambda fig, *a, **k: drawn.append(fig))

    def result(name, family, cost, d, th):
        return SimpleNamespace(name=name, family=family, instructions=cost, worst_d=d, worst_th=th, evaluations=None)

    layout = SimpleNamespace(name="paper", floor_rms=np.array([0.008, 0.008, 0.009, 0.9, 0.9]),
                             results=[result("ours, BIC", "ours", 400, 0.08, 2.9),
                                      result("mlp 64-64 tanh", "mlp", 30000, 0.13, 1.6),
                                      result("abess", "abess", 1200, 5.8, 7000.0)])
    estimators.plot([layout], tmp_path)
    fig = drawn[0]
    fig.canvas.draw()
    assert all(ax.get_legend() is None for ax in fig.axes) and len(fig.legends) == 1
    shown = {t.get_text() for ax in fig.axes for t in ax.yaxis.get_ticklabels() + ax.yaxis.get_ticklabels(minor=True)}
    assert not any("times" in t or "^" in t for t in shown) and "1" in shown, shown


def test_bench_noise_averaging_shows_the_line_it_draws_over_and_names_its_reference_lines(tmp_path, monkeypatch):
    """bench/noise_averaging.py --plot (docs/calibration.md's figure): `told` is 16 samples for every unit at the two
    higher flicker floors, and its line, drawn last in the same style, hid 16's there; the dashed lines (the 0.03 mm
    line, identify's refusal at 3, 1) were named nowhere."""
    from pathlib import Path

    import matplotlib.figure

    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1] / "bench"))
    import noise_averaging as na

    drawn = []
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", lambda fig, *a, **k: drawn.append(fig))
    # docs/calibration.md's table: (error / standard error, reduced chi-square, offset z) per floor and samples
    table = {16: [(1.04, 0.96, 0.0193), (0.97, 1.0, 0.0194), (1.06, 1.09, 0.0194), (1.09, 1.38, 0.0184)],
             128: [(0.83, 0.99, 0.0134), (1.19, 1.09, 0.0263), (1.11, 1.5, 0.0233), (1.63, 2.71, 0.039)],
             na.TOLD: [(1.0, 1.05, 0.0152), (0.99, 1.07, 0.0185), (1.06, 1.09, 0.0194), (1.09, 1.38, 0.0184)]}
    na._plot({(f, s): table[s][i] for s in table for i, f in enumerate(na.FLICKER)}, tmp_path)
    for ax in drawn[0].axes:
        lines = {line.get_label(): line for line in ax.get_lines()}
        sixteen, told = lines["16 samples per row"], lines["as tactile-host noise tells"]
        assert (told.get_marker(), told.get_linestyle()) != (sixteen.get_marker(), sixteen.get_linestyle())
        assert told.get_markerfacecolor() == "none"  # 16's marker seen through it
        said = [t.get_text() for t in ax.get_legend().get_texts()]
        assert len(said) == 4, said  # the three runs and the reference line


def test_bench_drift_draws_the_compensated_estimates_where_they_can_be_seen(tmp_path):
    """bench/drift.py --plot (docs/live.md's figure): "both" (auto-zero and the compensation) was drawn before "noise
    only" and as wide, and the two agree to within the noise, so the compensated trace, the figure's point, was
    hidden under the grey one: the legend named a line no reader could find."""
    from pathlib import Path

    import matplotlib.figure

    root = Path(__file__).resolve().parents[1]
    with pytest.MonkeyPatch.context() as mp:
        mp.syspath_prepend(str(root / "bench"))
        import drift

        drawn = []
        mp.setattr(matplotlib.figure.Figure, "savefig", lambda fig, *a, **k: drawn.append(fig))
        t = np.linspace(0.0, 300.0, 50)
        run = {"t": t, "out": np.zeros((50, 5)), "updates": [10.0]}
        drift.plot({f: run for f in ("tare only", "both", "noise only")}, {"before": run, "now": run},
                   ("dx", "dy", "dz", "thx", "thy"), tmp_path)
    for ax in drawn[0].axes[:2]:
        lines = [line for line in ax.get_lines() if line.get_label() in ("both", "noise only")]
        assert [line.get_label() for line in lines] == ["noise only", "both"]  # both drawn over noise only
        assert lines[1].get_linewidth() < lines[0].get_linewidth()  # and noise only's edges seen beside it


def test_bench_units_figures_name_the_units_truth_and_say_what_is_not_estimated(tmp_path):
    """bench/units.py --plot (docs/calibration.md's two figures): the identified figure's axes read "drawn
    sensitivity [x drawing]" and "(identified - drawn)", where "drawn" meant a unit drawn at random beside "the
    drawing", the design (a reader took the one for the other); its y axes had no unit and its offsets x, y and z
    differed by colour alone; the held-out figure left the tilt of a workflow that estimates none an empty column."""
    from pathlib import Path

    import matplotlib.figure

    root = Path(__file__).resolve().parents[1]
    with pytest.MonkeyPatch.context() as mp:
        mp.syspath_prepend(str(root / "bench"))
        import units

        drawn = []
        mp.setattr(matplotlib.figure.Figure, "savefig", lambda fig, *a, **k: drawn.append(fig))
        names = [f"magnet offset from the elements' centre {a} [mm]" for a in "xyz"]
        names += [f"e{k} sensitivity [x drawing]" for k in range(1, 9)]
        head = f"twin, {units.HEAD[0]} poses, {units.HEAD[1]:g} mm"
        twin = {s: {"noisy_max": np.full(5, 0.04), "derived": {n: (1.0 + 0.01 * s, 0.01) for n in names},
                    "derived_truth": {n: 1.0 for n in names}} for s in (1, 2)}
        three = {s: {"noisy_max": np.array([0.1, 0.1, 0.1, np.nan, np.nan])} for s in (1, 2)}
        units.plot({head: twin, "direct, 40 three-axis rows": three}, tmp_path)
    heldout, identified = drawn
    said = [t.get_text() for t in heldout.axes[3].texts]
    assert said == ["not\nestimated"], said
    a1, a2, a3 = identified.axes
    assert all("drawn" not in text for text in _texts(identified)), _texts(identified)
    assert a1.get_ylabel().endswith("[x the drawing's]") and a2.get_ylabel().endswith("[mm]")
    markers = {c.get_label(): c.lines[0].get_marker() for c in a2.containers}
    assert len(set(markers.values())) == 3, markers


def test_bench_stiffening_ticks_the_c_it_measured_and_names_its_line(tmp_path):
    """bench/stiffening.py --plot (docs/calibration.md's figure): c was ticked every 0.0025 in four decimals
    (0.0000, 0.0025, ... 0.0200), crowded, where the bench measures 0, 0.005, 0.01 and 0.02; the dashed line was
    "issue 21's line", which says nothing of what it is."""
    from pathlib import Path

    import matplotlib.figure

    root = Path(__file__).resolve().parents[1]
    with pytest.MonkeyPatch.context() as mp:
        mp.syspath_prepend(str(root / "bench"))
        import stiffening

        drawn = []
        mp.setattr(matplotlib.figure.Figure, "savefig", lambda fig, *a, **k: drawn.append(fig))
        pts = [(c, 0.02 + c, 0.004 + c / 2) for c in (0.0, 0.005, 0.01, 0.02)]
        stiffening.plot({"travel": pts, "working": pts}, str(tmp_path))
    fig = drawn[0]
    fig.canvas.draw()
    for ax in fig.axes:
        assert [t.get_text() for t in ax.get_xticklabels()] == ["0", "0.005", "0.01", "0.02"]
    said = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert "the acceptance's 0.03 mm (issue 21)" in said, said
