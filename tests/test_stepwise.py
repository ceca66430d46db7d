"""The stepwise search against R's step() (the reference) and against a plain refit-every-candidate loop."""

import numpy as np
import pytest

from fitgen.fitting.fit import FitSettings, fit_model, within_cap
from fitgen.equations.model import Model
from rstep import r_step
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, pose_rng, random_poses, simulate, DEFAULT_RANGES
from fitgen.fitting.stepwise import compress, stepwise, stepwise_reference
from fitgen.equations.terms import DISPLACEMENTS, candidate_terms, design_matrix, initial_terms

from conftest import require_tool

PAPER = load_sensor("paper")


def _problem(ds, output, d=None):
    cands = candidate_terms(ds.n_inputs, output, d_terms=d is not None, positive=ds.inputs.min(axis=0) > 0)
    X = design_matrix(cands, ds.inputs, d)
    init = [cands.index(t) for t in initial_terms(ds.n_inputs)]
    return cands, X, ds.target(output), init


def _compare_with_r(ds, k=2.0, ties=False):
    """Our search against R's step() on every output of ``ds``: the same AIC at every step, and the same terms.
    ``ties``: ``ds`` is symmetric (a mirror pair of elements on the ring, a grid symmetric about the mirror), so
    candidates tie in exact arithmetic; each search breaks such a tie by its rounding (ours by the CPU's BLAS
    kernel: with OpenBLAS's Sandybridge kernel dx takes v1's mirror term where R takes v1's), and the mirrored path
    scores the same at every step. There the terms may differ, and R's scores as ours when we refit it."""
    require_tool("Rscript")
    model = fit_model(ds, settings=FitSettings.exact(k=k))
    d = Model(model.input_min, model.input_max,
              tuple(model.equation(x) for x in DISPLACEMENTS)).predict(ds.inputs)
    for out in ds.target_names:
        cands, X, y, init = _problem(ds, out, d if out in ("thx", "thy") else None)
        ours = stepwise(X, y, init, k=k)
        ref = r_step(X, y, init, k=k)
        assert ours.aic == pytest.approx(ref["aic"], rel=1e-6, abs=1e-6), out
        np.testing.assert_allclose([t.aic for t in ours.trace], ref["trace"], rtol=1e-9, atol=1e-6, err_msg=out)
        if not ties or sorted(ours.selected) == sorted(ref["selected"]):
            assert sorted(ours.selected) == sorted(ref["selected"]), out
        else:  # a tie broken the other way: R's terms, refitted here, are as good as ours
            theirs = stepwise(X, y, ref["selected"], k=k, max_steps=0)
            assert theirs.aic == pytest.approx(ours.aic, rel=1e-9, abs=1e-6), out
            assert len(ours.selected) == len(ref["selected"]), out
        # and the model the fit produced is our selection
        assert {t.text for t in model.equation(out).terms} == {cands[j].text for j in ours.selected}


def test_same_choices_as_r_on_the_paper_grid():
    _compare_with_r(simulate(PAPER, grid_poses(PAPER_GRIDS["paper-sim"])), ties=True)


def test_same_choices_as_r_on_noisy_random_poses_and_bic():
    poses = random_poses(600, DEFAULT_RANGES, pose_rng(11))
    ds = simulate(PAPER, poses, noise=0.002, seed=11)
    _compare_with_r(ds)
    _compare_with_r(simulate(PAPER, poses[:300], noise=0.002, seed=12), k=float(np.log(300)))


def test_fast_search_equals_the_plain_refit_loop():
    rng = np.random.default_rng(5)
    poses = random_poses(250, DEFAULT_RANGES, rng)
    ds = simulate(PAPER, poses, noise=0.003, seed=5)
    for out, cap, exchange in (("dx", None, True), ("dz", 18, True), ("dx", 3, True), ("dx", 3, False),
                               ("dz", 18, False)):
        _, X, y, init = _problem(ds, out)
        init = within_cap(compress(X, y), init, cap or len(init))[0]
        fast = stepwise(X, y, init, max_terms=cap, exchange=exchange)
        slow = stepwise_reference(X, y, init, max_terms=cap, exchange=exchange)
        assert fast.selected == slow.selected
        np.testing.assert_allclose([s.aic for s in fast.trace], [s.aic for s in slow.trace], rtol=1e-9)
        assert [s.move for s in fast.trace] == [s.move for s in slow.trace]
        if cap:  # at the cap the search exchanged terms, which it had no move for, where it may
            assert len(fast.selected) <= cap and any(" + " in s.move for s in fast.trace) == exchange, out


def test_at_the_cap_exchanges_reach_the_best_subset_abess_finds():
    """abess (best subset of a given size by splicing, written elsewhere) as the peer: a search capped at k and started
    from k wrong columns ends on abess's k columns; one that only drops and adds kept the wrong ones."""
    from abess.linear import LinearRegression

    n, m, k = 300, 30, 4
    for seed in range(6):
        rng = np.random.default_rng(seed)
        X = rng.normal(size=(n, m)) + 0.35 * rng.normal(size=(n, 6)) @ rng.normal(size=(6, m))  # correlated columns
        true = sorted(rng.choice(m, k, replace=False).tolist())
        y = X[:, true] @ (rng.uniform(0.5, 2, k) * rng.choice([-1, 1], k)) + 0.3 * rng.normal(size=n)
        peer = np.flatnonzero(LinearRegression(support_size=[k]).fit(X, y).coef_).tolist()
        wrong = [j for j in range(m) if j not in true][:k]
        assert sorted(stepwise(X, y, wrong, max_terms=k).selected) == peer, seed


def test_at_the_cap_a_column_in_the_models_span_is_no_exchange():
    """A duplicate of a term (two channels wired to one element) had been swapped for it and back, on rounding alone,
    until max_steps: 1,000 moves in the model file's trace, and the duplicate listed as aliased while selected."""
    for seed in range(12):
        rng = np.random.default_rng(seed)
        X = rng.normal(size=(100, 6))
        y = X @ np.array([5.0, 3, 0.5, 0, 0, 0]) + 0.5 * rng.normal(size=100)
        for extra in (X[:, :1], X[:, :1] + X[:, 1:2]):  # a copy of a term; the sum of two
            res = stepwise(np.column_stack([X, extra]), y, [], max_terms=2)
            # (which of two equal columns is added first goes by rounding, as R's ties do: no reference to compare with)
            assert len(res.trace) <= 4 and not set(res.selected) & set(res.aliased), (seed, res.trace)


def test_without_a_cap_the_n_minus_2_limit_makes_no_exchange():
    """On 19 rows the limit of n - 2 terms binds, and the search without --max-terms had exchanged terms there
    (- v1^-2 + v3^-4), which R's step(), the uncapped search's peer, never does."""
    ds = simulate(PAPER, random_poses(19, DEFAULT_RANGES, pose_rng(5)))
    for settings in (FitSettings.exact(), FitSettings.exact(max_terms=17)):
        info = fit_model(ds, settings=settings).fit_info
        moves = [m for out in DISPLACEMENTS for m, _ in info["outputs"][out]["steps"]]
        assert any(" + " in m for m in moves) == (settings.max_terms is not None), moves


def test_a_cap_of_one_ends_at_the_best_single_candidate():
    """At the cap the search could only drop terms: --max-terms 1 kept eq. 1's best term, however much better
    another candidate fitted alone."""
    ds = simulate(PAPER, random_poses(250, DEFAULT_RANGES, pose_rng(5)), noise=0.003, seed=5)
    for out in ("dx", "dz", "thx"):
        cands, X, y, init = _problem(ds, out)
        single = [float(np.sum((y - np.polyval(np.polyfit(X[:, j], y, 1), X[:, j])) ** 2)) for j in range(len(cands))]
        got = fit_model(ds, (out,), FitSettings.exact(max_terms=1))
        assert [t.text for t in got.equation(out).terms] == [cands[int(np.argmin(single))].text], out


def test_aliased_columns_are_never_added_and_ties_take_candidate_order():
    rng = np.random.default_rng(0)
    a = rng.normal(size=200)
    b = rng.normal(size=200)
    y = 3 * a + 0.1 * rng.normal(size=200)
    # column 1 is -column 0: an exact tie on adding, then aliased; column 2 = 2*col3 aliased once 3 is in
    X = np.column_stack([a, -a, 2 * b, b])
    res = stepwise(X, y, [])
    assert res.selected[0] == 0
    assert 1 not in res.selected
    assert 1 in res.aliased


def test_a_start_with_aliased_terms_records_r_s_aic_at_every_step():
    """Two channels alike (v2 = v1): eq. 1 starts with aliased terms. The trace recorded their start with the RSS
    a QR's arbitrary column for the aliased one took up, and the penalty of every term: AICs below R's, rising
    over the forced drops where R's stay level. The end was right; now the whole trace is R's."""
    require_tool("Rscript")
    ds = simulate(PAPER, random_poses(300, DEFAULT_RANGES, pose_rng(11)))
    ds.inputs[:, 1] = ds.inputs[:, 0]
    cands, X, y, init = _problem(ds, "dz")
    ours = stepwise(X, y, init)
    ref = r_step(X, y, init)
    assert len(ours.aliased) >= 2 and sorted(ours.selected) == sorted(ref["selected"])
    np.testing.assert_allclose([t.aic for t in ours.trace], ref["trace"], rtol=0, atol=1e-6)


def test_compress_preserves_inner_products():
    rng = np.random.default_rng(1)
    X = rng.normal(size=(50000, 7)) * np.logspace(-3, 3, 7)
    y = rng.normal(size=50000)
    R = compress(X, y, block=4096)
    A = np.column_stack([np.ones(50000), X, y])
    np.testing.assert_allclose(R.T @ R, A.T @ A, rtol=1e-10, atol=1e-6)
    assert np.allclose(np.tril(R, -1), 0)


def test_a_gram_fold_is_the_qr_of_the_stacked_rows():
    """compress(gram=B^T B) gives the triangle of [1, X, y] and the rows [0, B, 0] that a QR of the stacked
    rows gives (rows up to sign), with columns eight orders of magnitude apart, and the search chooses alike."""
    rng = np.random.default_rng(3)
    n, m = 3000, 12
    X = rng.normal(size=(n, m)) * np.logspace(-4, 4, m)
    y = X[:, 1] * 300 + X[:, 6] * 2e-2 - X[:, 9] * 1e-3 + rng.normal(size=n)
    B = rng.normal(size=(8 * n, m)) * np.logspace(-7, 1, m)  # noise rows: ~1e-3 of each column or less
    stacked = np.zeros((B.shape[0], m + 2))
    stacked[:, 1:-1] = B
    plain = compress(X, y, extra=[stacked])
    folded = compress(X, y, gram=B.T @ B)
    size = np.linalg.norm(plain, axis=0)
    assert np.all(np.abs(np.abs(folded) - np.abs(plain)) <= 1e-10 * size)
    a, b = stepwise(None, y, [0], compressed=plain), stepwise(None, y, [0], compressed=folded)
    assert a.selected == b.selected and len(a.selected) >= 3
    assert a.aic == pytest.approx(b.aic, rel=1e-12)
