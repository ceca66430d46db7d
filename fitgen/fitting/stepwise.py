"""Bidirectional stepwise regression on AIC, as R's ``step(direction = "both")`` does it.

The data enter once: a Householder QR of [1, all candidates, y], taken in blocks of
rows, compresses the n rows into an (m+2)-row triangle with the same inner products.
Every later step works on that small triangle, so a step costs the same at 2,000 or
200,000 rows and no normal equations are formed. At each step all additions are
scored at once (candidates' residuals against the current basis, orthogonalised
twice) and all removals from the current triangular factor.

AIC = n log(RSS / n) + k * (terms + 1), R's ``extractAIC`` for ``lm``; the paper's
n ln(Se) + 2p differs from it by a constant, so both choose alike.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import eigh, get_lapack_funcs, qr, solve_triangular
from threadpoolctl import ThreadpoolController

# Threaded OpenBLAS is slower here at every size we meet (~100 columns): on a loaded
# machine a 1,875 x 117 QR took 1.3 s with threads against 15 ms on one. Every
# entry point below runs its linear algebra on one BLAS thread.
# The controller scans the loaded libraries once (about 1 ms); each limit then costs ~20 us.
_BLAS = ThreadpoolController()
_ONE_THREAD = _BLAS.wrap(limits=1, user_api="blas")
one_blas_thread = _ONE_THREAD  # for the fit's linear algebra outside this module (fitgen.fitting.augment)

ALIAS_TOL = 1e-7  # relative residual norm below which a column is aliased (R's lm.fit tol)
_BLOCK = 1 << 14  # rows per block of the compressing QR
_GEQRF = get_lapack_funcs("geqrf", dtype=np.float64)


@_ONE_THREAD
def compress(columns, y: np.ndarray, block: int = _BLOCK, extra=(), start: np.ndarray | None = None,
             gram: np.ndarray | None = None) -> np.ndarray:
    """Upper-triangular R with R^T R = A^T A for A = [1, columns, y], built block by block.

    ``columns``: the (n, m) candidate columns, or a function (lo, hi) -> the columns of rows lo..hi,
    so that they never need to be in memory all at once. ``extra``: further rows of A, already
    formed (m + 2 columns each), as an iterable of blocks. ``gram``: the (m, m) Gram matrix of
    further rows that are 0 in the intercept and y columns (the expected effect of noise,
    fitgen.fitting.augment), folded in last through :func:`gram_root`. ``start``: a triangle to fold the
    rows into (the compression is associative). Peak memory is one block of rows, whatever n is.
    """
    acc = start
    n = len(y)
    for lo in range(0, n, block):
        hi = min(n, lo + block)
        cols = columns(lo, hi) if callable(columns) else columns[lo:hi]
        if acc is None:
            acc = np.zeros((0, cols.shape[1] + 2))
        k = acc.shape[0]
        # the block is written straight into the Fortran-ordered array LAPACK factorises
        buf = np.empty((k + hi - lo, acc.shape[1]), order="F")
        buf[:k] = acc
        buf[k:, 0] = 1.0
        buf[k:, 1:-1] = cols
        buf[k:, -1] = y[lo:hi]
        del cols
        acc = _triangle(buf)
    for blk in extra:
        acc = _fold(acc, blk)
    if gram is not None:
        rows = np.zeros((gram.shape[0], gram.shape[0] + 2))
        rows[:, 1:-1] = gram_root(gram)
        acc = _fold(acc, rows)
    return acc


@_ONE_THREAD
def triangle(rows: np.ndarray) -> np.ndarray:
    """R of a Householder QR of ``rows``: upper triangular, with R^T R = rows^T rows."""
    return _triangle(np.array(rows, order="F", dtype=float))


def _fold(acc: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The triangle of [acc; rows]."""
    buf = np.empty((acc.shape[0] + rows.shape[0], acc.shape[1]), order="F")
    buf[: acc.shape[0]] = acc
    buf[acc.shape[0]:] = rows
    return _triangle(buf)


def _triangle(buf: np.ndarray) -> np.ndarray:
    """R of a Householder QR of ``buf`` (Fortran order; overwritten): LAPACK geqrf with the workspace it
    asks for, as scipy.linalg.qr(mode="r") calls it (so the same bits), without that function's copies
    and its triu of all the rows."""
    if not buf.size:
        return buf[: min(buf.shape)]
    lwork = int(_GEQRF(buf, lwork=-1, overwrite_a=True)[2][0])  # a query: buf is not touched
    qr_, _, _, info = _GEQRF(buf, lwork=lwork, overwrite_a=True)
    if info < 0:
        raise ValueError(f"illegal value in argument {-info} of geqrf")
    return np.triu(qr_[: min(buf.shape)])


def gram_root(gram: np.ndarray) -> np.ndarray:
    """S (m, m) with S^T S = ``gram``, a symmetric positive semi-definite matrix, to rounding.

    From the eigendecomposition of the gram with its diagonal scaled to 1, so that a column's
    share is kept to rounding whatever its size against the others; eigenvalues below 0, which
    only rounding makes, count as 0.
    """
    scale = np.sqrt(np.diag(gram))
    scale[scale == 0] = 1.0
    w, V = eigh(gram / scale[:, None] / scale[None, :], check_finite=False)
    return (np.sqrt(np.clip(w, 0.0, None))[:, None] * V.T) * scale[None, :]


@dataclass
class Step:
    """One accepted move of the search (``move`` is '' for the start)."""

    move: str
    aic: float
    rss: float
    n_terms: int


@dataclass
class StepwiseResult:
    selected: list[int]  # candidate indices, in the order they stand in the model
    aic: float
    rss: float
    trace: list[Step] = field(default_factory=list)
    aliased: list[int] = field(default_factory=list)  # candidates skipped as aliased, at any step


def aic_of(rss: float, n: int, n_terms: int, k: float) -> float:
    return n * np.log(rss / n) + k * (n_terms + 1)


def _factor(A: np.ndarray, cols: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Thin QR of the intercept and ``cols`` of the compressed data: the one factor a step uses."""
    return qr(A[:, [0] + [c + 1 for c in cols]], mode="economic", check_finite=False)


def _aliased_in(A: np.ndarray, cols: list[int], R: np.ndarray) -> list[int]:
    """Columns of ``cols`` whose residual against the intercept and the columns before them is aliased.

    ``R`` is the triangle of :func:`_factor` for ``cols``: its diagonal is each column's residual norm.
    """
    if not cols:
        return []
    norms = np.linalg.norm(A[:, [c + 1 for c in cols]], axis=0)
    return [c for c, d, nrm in zip(cols, np.abs(np.diag(R))[1:], norms) if d <= ALIAS_TOL * nrm]


def _rss_drops(Q: np.ndarray, R: np.ndarray, y: np.ndarray, rss: float) -> np.ndarray:
    """RSS of the model without each of its columns (the intercept stays), from its factor."""
    beta = solve_triangular(R, Q.T @ y, check_finite=False)
    rinv = solve_triangular(R, np.eye(R.shape[0]), check_finite=False)
    # dropping column t raises RSS by beta_t^2 / [(R^T R)^-1]_tt = beta_t^2 / |row t of R^-1|^2
    return rss + beta[1:] ** 2 / np.sum(rinv[1:] ** 2, axis=1)


def stepwise(
    columns: np.ndarray,
    y: np.ndarray,
    initial: list[int],
    *,
    names: list[str] | None = None,
    k: float = 2.0,
    max_terms: int | None = None,
    max_steps: int = 1000,
    compressed: np.ndarray | None = None,
    progress=None,
    exchange: bool = True,
) -> StepwiseResult:
    """Choose columns of ``columns`` (n, m) for ``y`` by bidirectional stepwise AIC (``columns`` may be
    None when ``compressed``, the triangle of :func:`compress`, is given).

    Starts from ``initial`` (indices); each step takes the single addition or removal
    with the lowest AIC, stops when none lowers it. Ties go as in R: staying put, then
    removals in model order, then additions in candidate order. Aliased candidates
    (relative residual norm < 1e-7 against the current model) are never added. At ``max_terms`` a term may
    give way to another (an exchange), unless not ``exchange``.
    """
    A = compress(columns, y) if compressed is None else compressed
    m = A.shape[1] - 2
    with _BLAS.limit(limits=1, user_api="blas"):
        return _search(A, len(y), initial, names or [str(j) for j in range(m)], k, max_terms, max_steps, progress,
                       exchange)


def _search(A, n, initial, names, k, max_terms, max_steps, progress, exchange) -> StepwiseResult:
    m = A.shape[1] - 2
    col_norm = np.linalg.norm(A, axis=0)[1:-1]
    yc = A[:, -1]
    current = list(dict.fromkeys(initial))
    if max_terms is not None and len(current) > max_terms:
        raise ValueError(f"the initial model has {len(current)} terms, more than the cap of {max_terms}")

    def rss_of(cols):
        Q, R = _factor(A, cols)
        r = yc - Q @ (Q.T @ yc)
        r = r - Q @ (Q.T @ r)
        return float(r @ r), Q, R, r

    def scored(cols):
        """rss_of, and the AIC of ``cols`` as R's extractAIC takes it: on the columns' rank, the RSS of the columns
        that are not aliased (a QR's column for an aliased one is arbitrary, and took up residual)."""
        rss, Q, R, r = rss_of(cols)
        dead = _aliased_in(A, cols, R)
        live = [c for c in cols if c not in dead]
        rss_live = rss_of(live)[0] if dead else rss
        return rss, Q, R, r, aic_of(rss_live, n, len(live), k), rss_live

    rss, Q, R, r, aic, shown = scored(current)
    trace = [Step("", aic, shown, len(current))]
    aliased_seen: set[int] = set()
    visited = {frozenset(current)}
    for _ in range(max_steps):
        # R first drops a term of the current model that is aliased with the others (Df 0), the last one first
        dead = _aliased_in(A, current, R)
        if dead:
            current.remove(dead[-1])
            aliased_seen.add(dead[-1])
            rss, Q, R, r, aic, shown = scored(current)
            trace.append(Step(f"- {names[dead[-1]]}", aic, shown, len(current)))
            continue
        # row 0: stay; then removals in model order; then additions in candidate order
        scores, outside = [np.array([aic])], np.zeros(0, dtype=int)
        if current:
            drops = _rss_drops(Q, R, yc, rss)
            scores.append(aic_of(np.maximum(drops, 1e-300), n, len(current) - 1, k))
        at_cap = max_terms is not None and len(current) >= max_terms
        free = np.ones(m, dtype=bool)
        free[current] = False
        outside = np.flatnonzero(free)
        if outside.size and not at_cap:
            Z = A[:, outside + 1]
            Z = Z - Q @ (Q.T @ Z)
            Z = Z - Q @ (Q.T @ Z)
            znorm = np.linalg.norm(Z, axis=0)
            ok = znorm > ALIAS_TOL * col_norm[outside]
            aliased_seen.update(outside[~ok].tolist())
            Z, outside, znorm = Z[:, ok], outside[ok], znorm[ok]
            coef = (Z.T @ r) / znorm**2
            new_r = r[:, None] - Z * coef
            add_rss = np.sum(new_r * new_r, axis=0)
            scores.append(aic_of(np.maximum(add_rss, 1e-300), n, len(current) + 1, k))
        elif outside.size and current and exchange:
            # at the cap a term may still give way to a better one: with additions barred, a search that only drops
            # kept the first terms it took, and a cap of one could end worse than the best single candidate
            swap_rss, skipped = _swap_rss(A, Q, R, r, rss, outside, col_norm[outside])
            aliased_seen.update(outside[skipped].tolist())
            for c, j in _back_to(visited, current):  # a model left had a higher AIC: only rounding leads back
                swap_rss[current.index(c), np.searchsorted(outside, j)] = np.inf
            swap_aic = aic_of(np.maximum(swap_rss, 1e-300), n, len(current), k)
            scores.append(swap_aic.ravel())
        # argmin takes the first of exactly equal scores, as R's order() does; scores equal in exact arithmetic
        # (a mirror pair of elements on a symmetric ring) go by their rounding, which the CPU's BLAS kernel sets
        best = int(np.argmin(np.concatenate(scores)))
        if best == 0:
            break
        if best <= len(current):
            move, j = "- {}", current[best - 1]
            current.remove(j)
        elif at_cap:
            gone, taken = divmod(best - 1 - len(current), len(outside))
            move, j = f"- {names[current.pop(gone)]} + {{}}", int(outside[taken])
            current.append(j)
        else:
            move, j = "+ {}", int(outside[best - 1 - len(current)])
            current.append(j)
        visited.add(frozenset(current))
        new_rss, Q, R, r = rss_of(current)
        new_aic = aic_of(new_rss, n, len(current), k)
        trace.append(Step(move.format(names[j]), new_aic, new_rss, len(current)))
        if progress is not None:
            progress(len(trace) - 1, new_aic, len(current))
        aic, rss = new_aic, new_rss
        if len(trace) > 1 and new_aic >= trace[-2].aic + 1e-7:
            break  # R's guard against a move the refit does not confirm (R keeps the move, so do we)
    return StepwiseResult(current, aic, rss, trace, sorted(aliased_seen - set(current)))


def _back_to(visited, current) -> list[tuple[int, int]]:
    """The exchanges (term c out, candidate j in) that lead from ``current`` to a model in ``visited``."""
    now = set(current)
    pairs = [(now - v, v - now) for v in visited if len(v) == len(now)]
    return [(next(iter(c)), next(iter(j))) for c, j in pairs if len(c) == 1 and len(j) == 1]


def _swap_rss(A, Q, R, r, rss, outside, col_norm) -> tuple[np.ndarray, np.ndarray]:
    """RSS of the model with each of its columns (rows) exchanged for each ``outside`` candidate (columns), inf where
    the candidate is aliased against the others or lies in the model's span (the RSS would stay, in exact arithmetic,
    and rounding alone had swapped a duplicate column back and forth); and the candidates so left out of every one.

    Without column c the residual space gains u_c, the unit vector of Q R^-T e_c (in the model's span, orthogonal to
    its other columns), so the residual and each candidate's projection gain one component each along it."""
    rinv = solve_triangular(R, np.eye(R.shape[0]), check_finite=False)
    U = Q @ rinv[1:].T
    U /= np.linalg.norm(U, axis=0)
    Z0 = A[:, outside + 1]
    Z = Z0 - Q @ (Q.T @ Z0)
    Z = Z - Q @ (Q.T @ Z)
    g, H = U.T @ A[:, -1], U.T @ Z0
    zres = np.sum(Z * Z, axis=0)  # each candidate's residual against the whole model
    zz = zres[None, :] + H * H
    inside = np.sqrt(zres) <= ALIAS_TOL * col_norm
    ok = (np.sqrt(zz) > ALIAS_TOL * col_norm[None, :]) & ~inside[None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        swap = rss + g[:, None] ** 2 - ((Z.T @ r)[None, :] + H * g[:, None]) ** 2 / zz
    return np.where(ok, swap, np.inf), ~ok.any(axis=0)


@_ONE_THREAD
def refit(compressed: np.ndarray, selected: list[int]) -> tuple[float, np.ndarray, float, float]:
    """Least squares with an intercept on the ``selected`` candidates, by Householder QR.

    Works on the compressed triangle of :func:`compress`, which holds every inner
    product of the rows, so the answer is that of a QR of all n rows (RSS included)
    at a cost independent of n. Returns (intercept, coefficients, RSS, condition
    number of the column-equilibrated design).
    """
    X = compressed[:, [0] + [c + 1 for c in selected]]
    y = compressed[:, -1]
    scale = np.linalg.norm(X, axis=0)
    scale[scale == 0] = 1.0
    Q, R = qr(X / scale, mode="economic", check_finite=False)
    beta = solve_triangular(R, Q.T @ y, check_finite=False) / scale
    resid = y - X @ beta
    sv = np.linalg.svd(R, compute_uv=False)
    cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
    return float(beta[0]), beta[1:], float(resid @ resid), cond


def stepwise_reference(columns: np.ndarray, y: np.ndarray, initial: list[int], *, k: float = 2.0,
                       max_terms: int | None = None, exchange: bool = True) -> StepwiseResult:
    """The plain way: refit every candidate model by least squares at every step.

    Same rules as :func:`stepwise`; kept as its independent check and its benchmark baseline.
    """
    n, m = columns.shape

    def rss(cols):
        X = np.column_stack([np.ones(n)] + [columns[:, c] for c in cols])
        beta, *_ = np.linalg.lstsq(X, y, rcond=None)
        r = y - X @ beta
        return float(r @ r)

    def aliased(cols, j):
        X = np.column_stack([np.ones(n)] + [columns[:, c] for c in cols])
        beta, *_ = np.linalg.lstsq(X, columns[:, j], rcond=None)
        return np.linalg.norm(columns[:, j] - X @ beta) <= ALIAS_TOL * np.linalg.norm(columns[:, j])

    current = list(initial)
    aic = aic_of(rss(current), n, len(current), k)
    trace = [Step("", aic, rss(current), len(current))]
    visited = {frozenset(current)}
    while True:
        moves = [("", aic)]
        moves += [(("-", c), aic_of(rss([x for x in current if x != c]), n, len(current) - 1, k)) for c in current]
        if max_terms is None or len(current) < max_terms:
            moves += [(("+", j), aic_of(rss(current + [j]), n, len(current) + 1, k))
                      for j in range(m) if j not in current and not aliased(current, j)]
        elif exchange:  # at the cap: exchanges, each term for each candidate outside the model's span, to a new model
            for c in current:
                rest = [x for x in current if x != c]
                moves += [((c, j), aic_of(rss(rest + [j]), n, len(current), k))
                          for j in range(m) if j not in current and not aliased(rest, j) and not aliased(current, j)
                          and frozenset(rest + [j]) not in visited]
        best = min(range(len(moves)), key=lambda i: (moves[i][1], i))
        if best == 0:
            break
        sign, j = moves[best][0]
        if sign not in ("-", "+"):
            sign, current = f"- {sign} +", [x for x in current if x != sign]
        current = [x for x in current if x != j] if sign == "-" else current + [j]
        visited.add(frozenset(current))
        aic = aic_of(rss(current), n, len(current), k)
        trace.append(Step(f"{sign} {j}", aic, rss(current), len(current)))
    return StepwiseResult(current, aic, rss(current), trace)
