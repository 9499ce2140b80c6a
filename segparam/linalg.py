"""Sparse linear algebra shared by the stages: one factorization helper for symmetric positive
definite systems, and one eigen-solver for the low end of a spectrum."""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable
from contextlib import AbstractContextManager

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .errors import SolverError

log = logging.getLogger(__name__)

#: Below this many rows a dense ``eigh`` is faster than factorizing.
DENSE_LIMIT = 400


@functools.cache
def _blas_controller():
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


@functools.lru_cache(maxsize=512)
def _syevr_workspace(n: int) -> tuple[int, int]:
    """LAPACK ``dsyevr``'s optimal workspace sizes for an ``n x n`` matrix (what
    ``scipy.linalg.eigh`` queries before each call)."""
    return tuple(int(x) for x in scipy.linalg.lapack.dsyevr_lwork(n, lower=1)[:2])


def lowest_pairs(A: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` smallest eigenpairs of a dense symmetric float64 ``A`` (lower triangle read):
    ``scipy.linalg.eigh(A, subset_by_index=[0, k - 1])``, the same LAPACK call (``dsyevr``,
    MRRR, with the workspace it would query) and the same bits, without its checks and its
    workspace query, which cost more than the problem below ~80 rows (2,000 blocks of 10 rows:
    0.10 s against 0.04 s). For the stages' many small per-chart problems.

    Raises
    ------
    numpy.linalg.LinAlgError
        If LAPACK reports a failure.
    """
    n = A.shape[0]
    lwork, liwork = _syevr_workspace(n)
    w, v, m, _isuppz, info = scipy.linalg.lapack.dsyevr(
        A, compute_v=1, range="I", lower=1, il=1, iu=k, lwork=lwork, liwork=liwork
    )
    if info != 0 or m != k or not np.isfinite(w[:k]).all():  # eigh rejects non-finite input
        raise np.linalg.LinAlgError(f"dsyevr failed on a {n} x {n} matrix (info {info})")
    return w[:k], v[:, :k]


def blas_threads(n: int) -> AbstractContextManager:
    """A context in which the BLAS libraries loaded so far run on at most ``n`` threads.

    The libraries are looked up once per process (``threadpool_limits`` looks them up on every
    call: 0.9 ms of CPU each, tens of calls per atlas); entering the context then costs 0.03 ms.
    """
    return _blas_controller().limit(limits=n, user_api="blas")


def one_blas_thread() -> AbstractContextManager:
    """:func:`blas_threads` (1): for the stages' many small dense problems, where threads only
    add overhead."""
    return blas_threads(1)


def spd_solver(A: sp.spmatrix) -> Callable[[np.ndarray], np.ndarray]:
    """Factorize a sparse symmetric positive definite matrix once; return ``B -> A^-1 B``.

    The factorization is CHOLMOD's supernodal Cholesky (through cvxopt, which ships it with
    OpenBLAS; AMD ordering). On the Hessian matrices of surface charts it is 2-5x faster than
    scipy's SuperLU: at 100k vertices 1.2-1.5 s against 2.9-4.1 s, at 300k 5.4-7.8 s against
    20-26 s (``python benchmarks/bench_solver.py --part factor``; a Cholesky factor is half an
    LU's size, and its supernodes run as dense BLAS-3 blocks); METIS nested dissection in front of
    it costs more than it saves.
    When cvxopt is missing, or ``A`` is not numerically positive definite (CHOLMOD stops at a
    non-positive pivot), it falls back to SuperLU's LU with a minimum-degree order on
    ``A + A^T``, which needs only a non-singular ``A``.

    Parameters
    ----------
    A : (n, n) sparse matrix
        Symmetric; positive definite for the Cholesky path.

    Returns
    -------
    solve : callable
        ``solve(B)`` for an (n,) or (n, r) float array returns ``A^-1 B``, same shape.
    """
    A = sp.csc_matrix(A)
    try:
        return _cholmod_solver(A)
    except (ImportError, ArithmeticError) as exc:
        log.debug("no Cholesky factorization (%r); factorizing with SuperLU", exc)
    return _lu_solver(A)


def _lu_solver(A: sp.csc_matrix) -> Callable[[np.ndarray], np.ndarray]:
    """:func:`spd_solver`'s fallback: SuperLU's LU with a minimum-degree order on ``A + A^T``."""
    lu = spla.splu(
        A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
    )
    return lu.solve


def spd_solver_entries(
    rows: np.ndarray, cols: np.ndarray, vals: np.ndarray, n: int
) -> Callable[[np.ndarray], np.ndarray]:
    """:func:`spd_solver` of the ``n x n`` matrix with these entries (both triangles, each entry
    once), without a scipy matrix on the Cholesky path: the entries below the diagonal go to
    CHOLMOD as they are (a small chart's Poisson matrix, many times an atlas: scipy's
    construction and ``tril`` cost more than the factorization)."""
    lower = rows >= cols
    try:
        return _cholmod_factor(vals[lower], rows[lower], cols[lower], n)
    except (ImportError, ArithmeticError) as exc:
        log.debug("no Cholesky factorization (%r); factorizing with SuperLU", exc)
    return _lu_solver(sp.csc_matrix((vals, (rows, cols)), shape=(n, n)))  # not CHOLMOD again


def _cholmod_solver(A: sp.csc_matrix) -> Callable[[np.ndarray], np.ndarray]:
    """:func:`spd_solver`'s Cholesky path; raises ImportError or ArithmeticError to fall back."""
    lower = sp.tril(A).tocoo()
    return _cholmod_factor(lower.data, lower.row, lower.col, A.shape[0])


def _cholmod_factor(
    data: np.ndarray, rows: np.ndarray, cols: np.ndarray, n: int
) -> Callable[[np.ndarray], np.ndarray]:
    """The CHOLMOD factorization of the matrix whose lower triangle has these entries."""
    from cvxopt import cholmod, matrix, spmatrix

    M = spmatrix(
        matrix(data.astype(np.float64)),
        matrix(rows.astype(np.intp)),
        matrix(cols.astype(np.intp)),
        (n, n),
    )
    factor = cholmod.symbolic(M, uplo="L")
    cholmod.numeric(M, factor)
    return _factor_solver(factor)


def _factor_solver(factor) -> Callable[[np.ndarray], np.ndarray]:
    """``B -> A^-1 B`` with a numeric CHOLMOD factor of A (cvxopt)."""
    from cvxopt import cholmod, matrix

    def solve(B: np.ndarray) -> np.ndarray:
        X = matrix(np.asarray(B, dtype=np.float64).reshape(len(B), -1))
        cholmod.solve(factor, X)
        return np.array(X).reshape(np.shape(B))

    return solve


class FixedPattern:
    """A sparse symmetric positive definite matrix whose pattern stays while its values change,
    factorized again for each new set of values: the fill-reducing order and the symbolic
    factorization are computed once (CHOLMOD through cvxopt), each refactorization is numeric
    only, and the values are summed into the pattern's slots without sorting.

    For iterations that solve one system per step (:func:`segparam.refine.slim_refine`): on a
    40k-row chart system the symbolic step cost 0.019 s against the numeric one's 0.035-0.053 s,
    and building the scipy matrix and its lower triangle for cvxopt 0.019 s more.

    Parameters
    ----------
    rows, cols : (k,) int ndarrays
        Entries of the lower triangle (``rows >= cols``), repeats allowed (they are summed).
    n : int
        Size of the matrix.
    slots : (slot, pattern_rows, pattern_cols) of int ndarrays, optional
        The layout a caller that knows its pattern's structure computed without sorting the
        entries (:func:`segparam.refine.proxy_layout`): every entry's slot, and the distinct
        entries in column-major order (rows ascending within a column), exactly what
        ``np.unique`` of the entries' column-major keys gives. ``rows`` and ``cols`` are then
        not read.
    """

    def __init__(
        self,
        rows: np.ndarray,
        cols: np.ndarray,
        n: int,
        *,
        slots: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> None:
        if slots is None:
            key = np.asarray(cols, dtype=np.int64) * n + np.asarray(rows, dtype=np.int64)
            unique, slot = np.unique(key, return_inverse=True)  # column-major: CSC order
            slots = (slot, unique % n, unique // n)
        # the entries' slots in the pattern, and the pattern's rows and columns (CSC order)
        self._slot, self._rows, self._cols = slots
        self.n = int(n)
        self._symbolic = None
        self._matrix = None  # the cvxopt matrix: its values are replaced, its pattern kept

    def solver(self, values: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """Factorize the matrix with these entry values (aligned with the constructor's
        entries); return ``B -> A^-1 B``, valid until the next call. Falls back to
        :func:`spd_solver` when cvxopt is missing or the matrix is not numerically positive
        definite."""
        data = np.bincount(self._slot, weights=values, minlength=len(self._rows))
        try:
            from cvxopt import cholmod, matrix, spmatrix

            if self._matrix is None:
                self._matrix = spmatrix(
                    matrix(data), matrix(self._rows.astype(np.intp)),
                    matrix(self._cols.astype(np.intp)), (self.n, self.n),
                )  # fmt: skip
                self._symbolic = cholmod.symbolic(self._matrix, uplo="L")
            else:  # the values in the matrix's own (column-major) order: the unique keys'
                self._matrix.V = matrix(data)
            cholmod.numeric(self._matrix, self._symbolic)
        except (ImportError, ArithmeticError) as exc:
            log.debug("no Cholesky refactorization (%r); factorizing anew", exc)
            lower = sp.csc_matrix((data, (self._rows, self._cols)), shape=(self.n, self.n))
            return spd_solver(lower + sp.tril(lower, -1).T)
        return _factor_solver(self._symbolic)


def smallest_eigenpairs(
    K: sp.spmatrix | np.ndarray,
    k: int,
    *,
    seed: int = 0,
    guess: np.ndarray | None = None,
    dense_limit: int = DENSE_LIMIT,
    tol: float = 1e-12,
    max_iter: int = 100,
) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` smallest eigenpairs of a symmetric positive semi-definite matrix.

    Small problems use dense ``scipy.linalg.eigh`` (:func:`lowest_pairs`). Large ones use block
    inverse (subspace) iteration with Rayleigh-Ritz on one factorization of ``K - sigma I``
    (:func:`spd_solver`): the wanted eigenvalues sit at the bottom of a spectrum whose scale grows
    like ``n^2`` (``K`` discretizes a fourth-order operator), so ``sigma`` is set just below zero,
    at ``-1e-3 mean(diag K) / n^2``, which keeps ``K - sigma I`` positive definite, and a random
    block of ``k + 2`` vectors converges in two solves, a block that starts near the wanted
    eigenvectors (`guess`) in one. (ARPACK's shift-invert mode with the same factorization needs
    several times more solves on these nearly degenerate null spaces.) A solve costs a tenth of the
    factorization or less per right-hand side, so the block is kept small.

    Parameters
    ----------
    K : (n, n) sparse matrix or ndarray
        Symmetric positive semi-definite.
    k : int
        Number of eigenpairs, ``k < n``.
    seed : int
        Seeds the random part of the start block, so the same input gives the same output.
    guess : (n, g) float ndarray, optional
        Vectors close to the wanted eigenvectors' span; the start block is these plus one random
        vector (sparse path only).
    dense_limit : int
        Largest ``n`` solved densely.
    tol : float
        Stop when every residual ``||K x - lambda x||`` is below ``tol * ||K||_1``.
    max_iter : int
        Most block iterations.

    Returns
    -------
    values : (k,) float64 ndarray
        Ascending.
    vectors : (n, k) float64 ndarray
        Orthonormal columns.

    Raises
    ------
    SolverError
        If the iteration does not converge.
    """
    n = K.shape[0]
    if k >= n:
        raise ValueError(f"asked for {k} eigenpairs of a {n} x {n} matrix")
    if n <= dense_limit:
        A = K.toarray() if sp.issparse(K) else np.asarray(K)
        # Threads only slow down a few-hundred-row eigh (5-8x measured on a busy 2-core box).
        with one_blas_thread():
            values, vectors = lowest_pairs(np.asarray(A, dtype=np.float64), k)
        return values, vectors
    K = sp.csc_matrix(K)
    norm = float(abs(K).sum(axis=0).max())
    sigma = -1e-3 * float(np.abs(K.diagonal()).mean()) / n**2
    shifted = (K - sigma * sp.identity(n, format="csc")).tocsc()
    solve = spd_solver(shifted)

    rng = np.random.default_rng(seed)
    if guess is None:
        X = rng.standard_normal((n, min(k + 2, n)))
    else:
        X = np.column_stack([guess, rng.standard_normal(n)])
    for it in range(max_iter):
        X = np.linalg.qr(solve(X))[0]
        values, W = np.linalg.eigh(X.T @ (K @ X))
        X = X @ W
        residual = np.linalg.norm(K @ X[:, :k] - X[:, :k] * values[:k], axis=0).max()
        if residual <= tol * norm:
            log.debug("subspace iteration: %d x %d converged in %d steps", n, n, it + 1)
            return values[:k], X[:, :k]
    raise SolverError(
        f"eigen-solver did not converge on a {n} x {n} matrix in {max_iter} steps "
        f"(residual {residual / norm:.1e} of ||K||)"
    )
