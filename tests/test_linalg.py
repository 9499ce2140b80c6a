"""The eigen-solver helper: sparse paths (minimum degree, nested dissection, start guess) agree
with a dense solve."""

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg
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


def test_fill_reducing_order_is_a_permutation_with_less_fill(K):
    # Vertices in random order (as a remeshed chart has them): nested dissection must beat it.
    n = K.shape[0]
    shuffle = np.random.default_rng(0).permutation(n)
    A = (K + 1e-6 * sp.identity(n)).tocsc()[shuffle][:, shuffle].tocsc()
    perm = linalg.fill_reducing_order(A)
    assert np.array_equal(np.sort(perm), np.arange(n))

    def fill(M):
        lu = scipy.sparse.linalg.splu(
            M, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
        )
        return lu.L.nnz + lu.U.nnz

    assert fill(A[perm][:, perm].tocsc()) < 0.5 * fill(A)


@pytest.mark.parametrize("nd_rows", [10**9, 0], ids=["minimum-degree", "nested-dissection"])
@pytest.mark.parametrize("with_guess", [False, True])
def test_sparse_paths_match_the_dense_solve(K, monkeypatch, nd_rows, with_guess):
    monkeypatch.setattr(linalg, "NESTED_DISSECTION_MIN_ROWS", nd_rows)
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
