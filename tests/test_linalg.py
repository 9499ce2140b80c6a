"""The linear-algebra helpers: both factorization paths (CHOLMOD, SuperLU) solve, and the sparse
eigen-solver agrees with a dense solve on each, with or without a start guess."""

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sp
from meshes import cylinder_patch

from segparam import linalg
from segparam.parameterize import hessian_matrix


@pytest.fixture(scope="module")
def K():
    V, F = cylinder_patch()  # a few hundred vertices: small enough for a dense reference
    return hessian_matrix(V, F)


def _reference(K, k):
    return scipy.linalg.eigh(K.toarray(), subset_by_index=[0, k - 1])


def _same_span(X, Y):
    """Cosines of the principal angles between two column spans are all 1."""
    Qx, Qy = np.linalg.qr(X)[0], np.linalg.qr(Y)[0]
    return np.linalg.svd(Qx.T @ Qy, compute_uv=False).min()


def _no_cholmod(A):
    raise ImportError("cvxopt hidden by the test")


def _no_superlu(*args, **kwargs):
    raise AssertionError("SuperLU used where CHOLMOD should be")


@pytest.fixture(params=["cholmod", "superlu"])
def path(request, monkeypatch):
    """Run a test once on each factorization path of ``spd_solver``, proving which one ran."""
    if request.param == "cholmod":
        monkeypatch.setattr(linalg.spla, "splu", _no_superlu)
    else:
        monkeypatch.setattr(linalg, "_cholmod_solver", _no_cholmod)
    return request.param


@pytest.mark.parametrize("shape", [(), (4,)], ids=["vector", "block"])
def test_spd_solver_solves(K, path, shape):
    n = K.shape[0]
    A = (K + 1e-3 * abs(K).sum(axis=0).max() * sp.identity(n)).tocsc()
    B = np.random.default_rng(1).standard_normal((n, *shape))
    X = linalg.spd_solver(A)(B)
    assert X.shape == B.shape
    np.testing.assert_allclose(A @ X, B, atol=1e-9 * np.abs(B).max())


def test_spd_solver_falls_back_on_an_indefinite_matrix():
    # Symmetric and non-singular but indefinite: Cholesky stops, the LU path must answer.
    A = sp.diags([2.0, -3.0, 4.0, 5.0]) + sp.diags([np.ones(3), np.ones(3)], [-1, 1])
    b = np.arange(1.0, 5.0)
    x = linalg.spd_solver(A)(b)
    np.testing.assert_allclose(A @ x, b, atol=1e-12)


def test_spd_solver_from_entries_is_spd_solver(K, monkeypatch):
    # The same matrix given as entries (both triangles, any order): the same lower triangle goes
    # to CHOLMOD, so the same solution to the last bit; without cvxopt, and on an indefinite
    # matrix, SuperLU's.
    n = K.shape[0]
    A = (K + 1e-3 * abs(K).sum(axis=0).max() * sp.identity(n)).tocoo()
    order = np.random.default_rng(0).permutation(A.nnz)
    rows, cols, vals = A.row[order], A.col[order], A.data[order]
    B = np.random.default_rng(1).standard_normal((n, 3))
    want = linalg.spd_solver(A.tocsc())(B)
    assert linalg.spd_solver_entries(rows, cols, vals, n)(B).tobytes() == want.tobytes()
    I = sp.diags([2.0, -3.0, 4.0, 5.0]) + sp.diags([np.ones(3), np.ones(3)], [-1, 1])
    I = I.tocoo()
    b = np.arange(1.0, 5.0)
    x = linalg.spd_solver_entries(I.row, I.col, I.data, 4)(b)
    np.testing.assert_allclose(I @ x, b, atol=1e-12)
    monkeypatch.setattr(linalg, "_cholmod_factor", _no_cholmod_factor)
    X = linalg.spd_solver_entries(rows, cols, vals, n)(B)
    np.testing.assert_allclose(A @ X, B, atol=1e-9 * np.abs(B).max())


def _no_cholmod_factor(*args):
    raise ImportError("cvxopt hidden by the test")


def test_fixed_pattern_refactorizes_new_values(K):
    """One pattern, two sets of values (repeated entries summed): each factorization solves its
    own matrix, the symbolic step of the first reused by the second; an indefinite set falls
    back to a fresh LU and still solves."""
    n = K.shape[0]
    lower = sp.tril(K).tocoo()
    rows = np.concatenate([lower.row, np.arange(n)])  # the diagonal twice: summed
    cols = np.concatenate([lower.col, np.arange(n)])
    pattern = linalg.FixedPattern(rows, cols, n)
    b = np.random.default_rng(2).standard_normal(n)
    shift = 1e-3 * abs(K).sum(axis=0).max()
    for scale, extra in ((1.0, shift), (3.0, 10 * shift), (1.0, -1e3 * shift)):
        values = np.concatenate([scale * lower.data, np.full(n, extra)])
        A = scale * K + extra * sp.identity(n)
        x = pattern.solver(values)(b)
        np.testing.assert_allclose(A @ x, b, atol=1e-8 * np.abs(b).max() * abs(A).max())
    assert pattern._symbolic is not None


@pytest.mark.parametrize("with_guess", [False, True])
def test_sparse_paths_match_the_dense_solve(K, path, with_guess):
    n = K.shape[0]
    guess = None
    if with_guess:
        guess = np.column_stack([np.ones(n), np.linspace(0, 1, n)])
    values, vectors = linalg.smallest_eigenpairs(K, 3, guess=guess, dense_limit=10)
    ref_values, ref_vectors = _reference(K, 3)
    scale = abs(K).sum(axis=0).max()
    np.testing.assert_allclose(values, ref_values, atol=1e-10 * scale)
    assert _same_span(vectors, ref_vectors) > 1 - 1e-8
    np.testing.assert_allclose(vectors.T @ vectors, np.eye(3), atol=1e-10)
