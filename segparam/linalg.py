"""The one eigen-solver helper, used by every stage that needs the low end of a spectrum."""

from __future__ import annotations

import logging

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .errors import SolverError

log = logging.getLogger(__name__)

#: Below this many rows a dense ``eigh`` is faster than factorizing.
DENSE_LIMIT = 400
#: From this many rows on, the factorization is ordered by METIS nested dissection. Below it
#: SuperLU's minimum degree is as good and skips the ordering's overhead (best of 3, ordering +
#: factorization: 0.25 / 0.32 s at 20k rows, 0.88 / 0.81 s on a 35k-vertex folded chart, 1.38 /
#: 1.31 s at 50k on a sheet, 2.4 / 1.45 s on a 50k-vertex folded chart).
NESTED_DISSECTION_MIN_ROWS = 40_000


def fill_reducing_order(A: sp.spmatrix) -> np.ndarray:
    """METIS nested-dissection ordering of a structurally symmetric sparse matrix.

    On the Hessian matrices of surface charts (2-ring sparsity) it leaves ~25% less fill in the
    factors than SuperLU's own minimum-degree ordering (``MMD_AT_PLUS_A``), and factorizing with
    it takes half the time: at 100k vertices 25.8M against 33.6M non-zeros in L + U, 2.2 s
    against 4.1-4.7 s, plus 1.0-1.2 s for the ordering itself (``benchmarks/bench_solver.py``).

    Returns
    -------
    perm : (n,) int64 ndarray
        ``A[perm][:, perm]`` is the matrix to factorize.
    """
    import pymetis

    G = sp.csr_matrix(A, copy=True)
    G.setdiag(0)
    G.eliminate_zeros()
    G.sort_indices()
    adjacency = pymetis.CSRAdjacency(G.indptr.astype(np.int64), G.indices.astype(np.int64))
    perm, _ = pymetis.nested_dissection(adjacency)
    return np.asarray(perm, dtype=np.int64)


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

    Small problems use dense ``scipy.linalg.eigh``. Large ones use block inverse (subspace)
    iteration with Rayleigh-Ritz on a sparse LU factorization of ``K - sigma I`` (ordered by
    :func:`fill_reducing_order` from ``NESTED_DISSECTION_MIN_ROWS`` rows on): the wanted
    eigenvalues sit at the bottom of a spectrum whose scale grows like ``n^2`` (``K`` discretizes a
    fourth-order operator), so ``sigma`` is set just below zero, at ``-1e-3 mean(diag K) / n^2``,
    and a random block of ``k + 2`` vectors converges in two solves, a block that starts near the
    wanted eigenvectors (`guess`) in one. (ARPACK's shift-invert mode with the same factorization
    needs several times more solves on these nearly degenerate null spaces.) Each solve costs about
    as much per right-hand side as a tenth of the factorization (0.07-0.1 s per column against
    2 s at 100k rows), so the block is kept small.

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
        from threadpoolctl import threadpool_limits  # installed with scikit-learn

        A = K.toarray() if sp.issparse(K) else np.asarray(K)
        # Threads only slow down a few-hundred-row eigh (5-8x measured on a busy 2-core box).
        with threadpool_limits(limits=1, user_api="blas"):
            values, vectors = scipy.linalg.eigh(A, subset_by_index=[0, k - 1])
        return values, vectors
    K = sp.csc_matrix(K)
    norm = float(abs(K).sum(axis=0).max())
    sigma = -1e-3 * float(np.abs(K.diagonal()).mean()) / n**2
    shifted = (K - sigma * sp.identity(n, format="csc")).tocsc()
    perm = fill_reducing_order(shifted) if n >= NESTED_DISSECTION_MIN_ROWS else None
    lu = spla.splu(
        shifted if perm is None else shifted[perm][:, perm].tocsc(),
        permc_spec="MMD_AT_PLUS_A" if perm is None else "NATURAL",
        diag_pivot_thresh=0.0,
        options={"SymmetricMode": True},
    )

    def solve(B: np.ndarray) -> np.ndarray:
        if perm is None:
            return lu.solve(B)
        out = np.empty_like(B)
        out[perm] = lu.solve(B[perm])
        return out

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
