"""core.csc's numpy-only CSC matrix, which the verifier builds bilinear relaxations with, against
scipy.sparse's, which the solver builds them with: the same pattern from the same triplets, and the
products a safe bound takes (a dense matrix times the matrix, its absolute values and its pattern)
equal to the last bit, so a bound the verifier recomputes is the one scipy's matrix would give."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from geocert.formulations.bilinear.relaxation import Relaxation, insert_row, with_cost_cap
from geocert.core.cones import safe_lower_bounds
from geocert.core.csc import CscMatrix


def relaxations(norm: str, coefficients: str, seed: int):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(3, 9, 3)) * 10.0 ** rng.uniform(-3, 3, size=(3, 9, 3))
    u = rng.normal(size=(9, 2)) * 100
    lo = rng.uniform(-2, 0, size=6)
    hi = lo + rng.uniform(0, 2, size=6)
    lo[0] = 0.0  # explicit zeros among McCormick's coefficients
    args = (X, u, norm, coefficients, 2.0)
    theirs, ours = Relaxation(*args), Relaxation(*args, matrix=CscMatrix)
    cap = 1e6
    plain = (theirs.conic_data(lo, hi, cap), ours.conic_data(lo, hi, cap))
    return [plain, (with_cost_cap(theirs, plain[0], cap), with_cost_cap(ours, plain[1], cap))]


@pytest.mark.parametrize("norm", ["L1L1", "L2L2"])
@pytest.mark.parametrize("coefficients", ["convex", "bounded"])
def test_the_relaxations_matrix_and_its_products_are_scipys_to_the_last_bit(norm, coefficients):
    for seed in range(3):
        for theirs, ours in relaxations(norm, coefficients, seed):
            A, B = theirs.A.tocsc(), ours.A
            assert isinstance(B, CscMatrix) and sp.issparse(A)
            assert B.shape == A.shape and B.nnz == A.nnz
            assert np.array_equal(B.indptr, A.indptr) and np.array_equal(B.indices, A.indices)
            assert np.array_equal(B.data, A.data)
            rng = np.random.default_rng(seed)
            Z = rng.normal(size=(4, A.shape[0])) * 10.0 ** rng.uniform(-8, 8, size=(4, A.shape[0]))
            Z[:, rng.random(A.shape[0]) < 0.3] = 0.0
            for left in (Z, Z[0], np.abs(Z)):
                assert np.asarray(left @ A).tobytes() == (left @ B).tobytes()
            assert (np.abs(Z) @ abs(A)).tobytes() == (np.abs(Z) @ abs(B)).tobytes()
            pattern = (np.abs(Z) != 0).astype(float)
            assert np.asarray(pattern @ (abs(A) != 0).astype(float)).tobytes() == \
                (pattern @ (abs(B) != 0).astype(float)).tobytes()
            Q = rng.normal(size=(4, A.shape[1]))
            args = (theirs.b, theirs.cones, Z, theirs.lower, theirs.upper)
            assert safe_lower_bounds(Q, A, *args).tobytes() == safe_lower_bounds(Q, B, *args).tobytes()


def test_a_row_inserted_as_into_scipys():
    rng = np.random.default_rng(1)
    dense = np.where(rng.random((7, 5)) < 0.4, rng.normal(size=(7, 5)), 0.0)
    A = sp.csc_matrix(dense)
    B = CscMatrix((A.data, A.indices, A.indptr), A.shape)
    assert np.array_equal(B.toarray(), dense)
    for at in (0, 3, 7):
        theirs, ours = insert_row(A, at, np.array([0, 2, 4])), insert_row(B, at, np.array([0, 2, 4]))
        assert isinstance(ours, CscMatrix)
        assert np.array_equal(ours.toarray(), theirs.toarray())
        assert np.array_equal(ours.indices, theirs.indices) and np.array_equal(ours.indptr, theirs.indptr)


def test_its_triplets_order_is_scipys_conversion():
    rng = np.random.default_rng(2)
    cells = rng.permutation(40 * 30)[:300]
    rows, cols = cells // 30, cells % 30
    ours, order = CscMatrix.from_triplets(rows, cols, (40, 30))
    theirs = sp.csc_matrix((np.arange(1, 301, dtype=float), (rows, cols)), shape=(40, 30))
    assert np.array_equal(ours.indptr, theirs.indptr) and np.array_equal(ours.indices, theirs.indices)
    assert np.array_equal(order, theirs.data.astype(np.int64) - 1)
