"""Every relaxation under-estimates: at random points of random boxes, bound <= true cost."""

import contextlib

import numpy as np
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from geocert.formulations.fractional import relaxation
from geocert.core.bnb import Box, BoxStatus
from geocert.solvers.fractional.search import Prepared
from geocert.solvers.fractional.triangulation import NORMS, TriangulationOptions, prepare_track

from tests.support import noisy_track, random_cameras


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    views=st.integers(2, 6),
    norm=st.sampled_from(NORMS),
    shrink=st.floats(0.01, 1.0),
    slack=st.floats(1.0, 4.0),
    full=st.booleans(),
    quadratic=st.booleans(),
)
def test_box_bound_never_exceeds_cost_inside_the_box(seed, views, norm, shrink, slack, full, quadratic):
    """Also with full certificates, where the bound is the safe bound of the dual vector, and
    under L2L2 with the quadratic envelope (Relaxation.quadratic, what maps search with)."""
    rng = np.random.default_rng(seed)
    cameras = random_cameras(rng, views)
    _, points = noisy_track(rng, cameras, noise_px=3.0)
    _, prepared = prepare_track(cameras, points, TriangulationOptions(norm=norm, certificate="full" if full else "summary"))
    if not isinstance(prepared, Prepared):
        return  # closed before any box exists (noiseless or degenerate): nothing to bound
    problem = prepared.problem
    problem.relaxation.quadratic = quadratic and norm == "L2L2"
    root = problem.root
    k = len(problem.B)  # branched directions: as many as the depths vary along (1 to 3)
    # A random sub-box of the root region, and random points inside it: z = B y in the box, and
    # along the directions not branched (where the residual cones bound the region) around the
    # incumbent, within their proven bounds when there are some.
    centre = root.lo + rng.uniform(size=k) * root.width
    half = 0.5 * shrink * root.width * rng.uniform(0.05, 1.0, size=k)
    box = Box(np.maximum(root.lo, centre - half), np.minimum(root.hi, centre + half))
    z = box.lo + rng.uniform(size=(200, k)) * box.width
    F, transform = problem.relaxation.F, problem.relaxation.transform
    w = F[k:] @ prepared.incumbent + rng.uniform(-1, 1, size=(200, 3 - k)) * shrink * np.max(root.width)
    w = np.clip(w, *problem.relaxation.complement)
    ys = np.hstack([z, w]) @ transform.T  # y = F^-1 [z; w]
    costs = np.array([problem.objective(y) for y in ys])
    finite = costs[np.isfinite(costs)]
    if finite.size == 0:
        return
    # The bound is only claimed for points costing at most the upper bound it is given.
    upper = float(np.min(finite)) * slack
    bound = problem.bound(box, upper)
    cheapest = float(np.min(finite))
    if bound.status == BoxStatus.BOUNDED:
        assert bound.lower_bound <= cheapest * (1 + 1e-6) + 1e-9
    else:
        # "empty" means no point of the box costs at most the upper bound: a sample contradicts it.
        assert bound.status != BoxStatus.EMPTY or cheapest > upper * (1 - 1e-9)


@contextlib.contextmanager
def dense_limit(value: int):
    """The size below which relaxations are assembled dense, set for the block's duration."""
    saved, relaxation._DENSE_LIMIT = relaxation._DENSE_LIMIT, value
    try:
        yield
    finally:
        relaxation._DENSE_LIMIT = saved


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), views=st.integers(2, 6), norm=st.sampled_from(NORMS), envelope=st.booleans(),
       quadratic=st.booleans())
def test_dense_and_sparse_assembly_build_the_same_matrix(seed, views, norm, envelope, quadratic):
    """Small relaxations are assembled dense, large ones sparse: both paths give the same A."""
    rng = np.random.default_rng(seed)
    cameras = random_cameras(rng, views)
    _, points = noisy_track(rng, cameras, noise_px=3.0)
    _, prepared = prepare_track(cameras, points, TriangulationOptions(norm=norm))
    if not isinstance(prepared, Prepared):
        return
    problem = prepared.problem
    problem.relaxation.quadratic = quadratic and norm == "L2L2"
    dense = problem.conic_data(problem.root, prepared.upper, envelope)
    with dense_limit(0):
        sparse = problem.conic_data(problem.root, prepared.upper, envelope)
    assert isinstance(dense.A, np.ndarray) and sp.issparse(sparse.A)
    assert np.array_equal(sparse.A.toarray(), dense.A)
    assert np.array_equal(sparse.b, dense.b) and sparse.cones == dense.cones


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), views=st.integers(2, 6), spoil=st.floats(0.0, 3.0))
def test_root_bounds_are_each_duals_safe_bound(seed, views, spoil):
    """relaxation.root_bounds takes every root dual's safe bound at once: each equals
    cones.safe_lower_bound of that dual alone, also for duals pushed out of the dual cone, and a
    dual holding inf or NaN bounds nothing (-inf below, +inf above), the others unaffected."""
    from geocert.core.cones import safe_lower_bound

    rng = np.random.default_rng(seed)
    cameras = random_cameras(rng, views)
    _, points = noisy_track(rng, cameras, noise_px=3.0)
    _, prepared = prepare_track(cameras, points, TriangulationOptions())
    if not isinstance(prepared, Prepared):
        return
    proof = prepared.root_proof
    region = relaxation.residual_region(prepared.problem.program, proof.gamma)
    F = proof.functionals
    duals = [np.asarray(z) + spoil * rng.normal(size=len(z)) * np.abs(z).max() for z in proof.duals]
    if rng.uniform() < 0.5:
        duals[int(rng.integers(len(duals)))][int(rng.integers(len(duals[0])))] = rng.choice([np.inf, np.nan])
    lower, upper = relaxation.root_bounds(region, F, duals, proof.claim_lower, proof.claim_upper)
    A, b, cones = region
    transform = np.linalg.inv(F)
    for j in range(len(F)):
        alone = [safe_lower_bound(F[j], A, b, cones, duals[2 * j], proof.claim_lower, proof.claim_upper, transform),
                 -safe_lower_bound(-F[j], A, b, cones, duals[2 * j + 1], proof.claim_lower, proof.claim_upper, transform)]
        for ours, theirs in zip((lower[j], upper[j]), alone):
            if np.isinf(theirs):
                assert ours == theirs
            else:
                assert abs(ours - theirs) <= 1e-12 * (1 + abs(theirs))
