"""The flat local solve (fractional/flat.py) and the convexity bound (fractional/convexity.py):
the local solve finds scipy's optimum, every proven bound lies below the global optimum (the
branch and bound's certified cost, and every local minimum found from many starts), the
Hessian bound (V) holds where it is claimed, and the positive-definiteness test is exact
enough."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.optimize

from geocert.formulations.fractional import flat as flat_tracks
from geocert.solvers.fractional.many_tracks import triangulate_many
from geocert.formulations.fractional.convexity import (PAIRS, bounds_at, convexity_bounds, outside_range, positive_definite,
                                                  track_bound)
from geocert.solvers.fractional.triangulation import TriangulationOptions

from tests.support import dinosaur_sample, noisy_track, random_cameras, seed



def scene(rng, tracks: int, views: tuple[int, int], noise: tuple[float, ...], cameras: int = 20):
    cams = random_cameras(rng, cameras)
    out = []
    for _ in range(tracks):
        k = int(rng.integers(views[0], views[1] + 1))
        chosen = sorted(rng.choice(cameras, size=k, replace=False).tolist())
        _, points = noisy_track(rng, cams[chosen], noise_px=float(rng.choice(noise)))
        out.append((chosen, points))
    return cams, out


def solve(cams, tracks):
    flat = flat_tracks.FlatTracks.build(cams, tracks)
    x0, ok = flat_tracks.linear(flat)
    x, cost = flat_tracks.refine(flat, x0)
    return flat, x, cost, ok


def reprojection(cams, X):
    proj = cams[:, :, :3] @ X + cams[:, :, 3]
    return proj[:, :2] / proj[:, 2:3]


@pytest.mark.parametrize("views", [(2, 2), (3, 5), (6, 20)])
def test_the_local_solve_finds_scipys_optimum(views):
    rng = np.random.default_rng(seed("flat", str(views)))
    cams, tracks = scene(rng, 60, views, (0.5, 3.0))
    _, x, cost, ok = solve(cams, tracks)
    assert ok.all()
    for t, (chosen, points) in enumerate(tracks):
        fit = scipy.optimize.least_squares(lambda X: (reprojection(cams[chosen], X) - points).ravel(), x[t],
                                           method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
        assert cost[t] <= 2 * fit.cost * (1 + 1e-9) + 1e-18, t  # scipy's cost is half the sum of squares


@pytest.fixture(scope="module")
def dinosaur():
    return dinosaur_sample(10)  # 499 tracks


def test_dinosaur_bounds_lie_below_the_certified_optimum_and_close_the_gap(dinosaur):
    cameras, tracks = dinosaur
    flat, x, cost, _ = solve(cameras, tracks)
    lower, radius, computed = convexity_bounds(flat, x)
    optimum = triangulate_many(cameras, tracks, TriangulationOptions(norm="L2L2", rel_gap=1e-3))
    best = np.array([result.cost for result in optimum])
    assert all(result.certified for result in optimum)
    assert np.all(lower <= best)  # never above the global optimum
    assert np.all(computed <= best * (1 + 1e-6))  # the local solve found it
    closed = computed - lower <= np.maximum(1e-7, 1e-3 * computed)
    assert closed.mean() >= 0.99  # the bound certifies nearly every track without a search
    assert np.all(np.isfinite(radius[np.isfinite(lower)]))


@pytest.mark.parametrize("noise", [(0.5,), (30.0, 100.0, 300.0)])
def test_no_bound_above_the_best_of_many_local_minima(noise):
    """Large noise makes tracks with several local minima; a bound proven at any of them lies
    below the best found from 30 random starts (and the linear start)."""
    rng = np.random.default_rng(seed("local minima", str(noise)))
    cams, tracks = scene(rng, 150, (2, 4), noise, cameras=6)
    flat = flat_tracks.FlatTracks.build(cams, tracks)
    points = [flat_tracks.refine(flat, flat_tracks.linear(flat)[0], iterations=60)]
    points += [flat_tracks.refine(flat, rng.normal(size=(len(tracks), 3)) * 3, iterations=60) for _ in range(30)]
    best = np.min([cost for _, cost in points], axis=0)
    several = 0
    for x, cost in points:
        lower, _, _ = convexity_bounds(flat, x)
        assert np.all(lower <= best)
        several += np.sum(np.isfinite(cost) & (cost > best * (1 + 1e-6)) & (np.abs(x).max(axis=1) < 1e3))
    if noise[0] > 1:
        assert several > 0  # there were local minima that are not global


def hessian(cams, X):
    """The cost's Hessian at X by central differences of its analytic gradient."""
    def gradient(Y):
        proj = cams[:, :, :3] @ Y + cams[:, :, 3]
        w = proj[:, 2]
        image = proj[:, :2] / w[:, None]
        r = image - points_of[0]
        J = (cams[:, :2, :3] - image[:, :, None] * cams[:, None, 2, :3]) / w[:, None, None]
        return 2 * np.einsum("iak,ia->k", J, r)
    step = 1e-6 * (1 + np.abs(X).max())
    return np.array([(gradient(X + step * e) - gradient(X - step * e)) / (2 * step) for e in np.eye(3)])


points_of: list = [None]


def in_C(cams, points, x, count, rng, rho):
    """Points of C = {every depth > 0, every residual <= rho}, sampled as back-projections of
    pixels within rho of each observation at depths from e^-3 to e^3 times the point's, most
    of them near it."""
    found = []
    for i in range(len(cams)):
        A, b = cams[i][:, :3], cams[i][:, 3]
        for _ in range(count):
            offset = rng.normal(size=2)
            pixel = points[i] + rho * rng.uniform() ** 0.5 * offset / np.linalg.norm(offset)
            spread = rng.uniform(-1, 1) * 10.0 ** rng.uniform(-6, 0.5)
            depth = np.exp(spread) * (cams[i][2] @ np.append(x, 1.0))
            X = np.linalg.solve(A, np.append(pixel, 1.0) * depth - b)
            proj = cams[:, :, :3] @ X + cams[:, :, 3]
            if np.all(proj[:, 2] > 0) and np.all(np.linalg.norm(proj[:, :2] / proj[:, 2:3] - points, axis=1) <= rho):
                found.append(X)
    return found


def narrow(rng, tracks: int, noise: float):
    """Cameras 8 units from the points with centres within 0.5 of each other: nearly parallel rays."""
    cams = random_cameras(rng, 6, spread=0.25)
    out = []
    for _ in range(tracks):
        chosen = sorted(rng.choice(6, size=int(rng.integers(2, 4)), replace=False).tolist())
        _, points = noisy_track(rng, cams[chosen], noise_px=noise)
        out.append((chosen, points))
    return cams, out


@pytest.mark.parametrize("noise", [0.5, 5.0])
def test_every_point_of_C_lies_inside_the_proven_ball(noise):
    """(E): where a bound is proven with radius R, no point whose residuals are all within rho
    lies R or more from the point."""
    rng = np.random.default_rng(seed("enclosure", str(noise)))
    cams_all, tracks = narrow(rng, 60, noise)
    flat, x, cost, _ = solve(cams_all, tracks)
    lower, radius, computed = convexity_bounds(flat, x)
    sampled = 0
    for t in np.flatnonzero(np.isfinite(lower)):
        chosen, points = tracks[t]
        for X in in_C(cams_all[chosen], points, x[t], 300, rng, np.sqrt(computed[t])):
            assert np.linalg.norm(X - x[t]) < radius[t]
            sampled += 1
    assert sampled > 1000


@pytest.mark.parametrize("noise", [1.0, 10.0, 40.0])
def test_the_hessian_is_above_S_on_the_balls_part_of_C(noise):
    """(V)'s inequality, from the docstring's formula without round-off allowances: at points
    of C within the ball |X - x| <= R (R half the distance to the nearest principal plane),
    v' H v >= v' S v for directions v that include each view's ray, where the cost curves
    least (S may be indefinite: the inequality holds regardless)."""
    rng = np.random.default_rng(seed("hessian", str(noise)))
    cams_all, tracks = narrow(rng, 40, noise)
    flat, x, cost, _ = solve(cams_all, tracks)
    checked = 0
    for t, (chosen, points) in enumerate(tracks):
        cams = cams_all[chosen]
        points_of[0] = points
        proj = cams[:, :, :3] @ x[t] + cams[:, :, 3]
        w = proj[:, 2]
        if not np.all(w > 0):
            continue
        image = proj[:, :2] / w[:, None]
        r = image - points
        rho = np.sqrt(np.sum(r * r))
        d = cams[:, 2, :3]
        M = cams[:, :2, :3] - image[:, :, None] * d[:, None, :]
        R = 0.5 * np.min(w / np.linalg.norm(d, axis=1))
        e = rho + np.linalg.norm(r, axis=1)
        rays = [np.linalg.svd(M[i])[2][-1] for i in range(len(cams))]
        for Y in [x[t]] + in_C(cams, points, x[t], 30, rng, rho):
            radius = np.linalg.norm(Y - x[t])
            if radius > R:
                continue
            lo, hi = w - radius * np.linalg.norm(d, axis=1), w + radius * np.linalg.norm(d, axis=1)
            S = sum(M[i].T @ M[i] / (2 * hi[i] ** 2) - (e[i] ** 2 / hi[i] ** 2 + 4 * rho ** 2 / lo[i] ** 2)
                    * np.outer(d[i], d[i]) for i in range(len(cams)))
            H = hessian(cams, Y)
            for v in rays + list(rng.normal(size=(3, 3))):
                scale = abs(v @ H @ v) + abs(v @ S @ v) + 1e-300
                assert v @ H @ v >= v @ S @ v - 1e-6 * scale
                checked += 1
    assert checked > 100


def test_positive_definite_agrees_with_eigenvalues():
    rng = np.random.default_rng(seed("positive definite"))
    B = rng.normal(size=(5000, 3, 3))
    A = B @ B.transpose(0, 2, 1) - rng.uniform(0, 2, size=(5000, 1, 1)) * np.eye(3)
    A *= 10.0 ** rng.uniform(-5, 5, size=(5000, 1, 1))
    smallest = np.linalg.eigvalsh(A)[:, 0]
    margin = 0.5 * smallest * rng.uniform(0, 2, size=5000)
    entries = np.stack([A[:, a, b] for a, b in PAIRS])
    said = positive_definite(entries, margin, np.zeros(5000))
    assert np.all(smallest[said] > margin[said])  # never a false yes
    clear = smallest > margin + 1e-6 * np.abs(A).sum(axis=(1, 2))
    assert np.all(said[clear])  # a clear yes is seen
    allowed = positive_definite(entries, margin, 0.2 * np.abs(smallest))
    assert np.all(smallest[allowed] > margin[allowed] + 0.6 * np.abs(smallest[allowed]) * (1 - 1e-9))


def _rotated(rng, values: np.ndarray) -> np.ndarray:
    """Symmetric matrices Q diag(values) Q' with Q random rotations: values (N, 3)."""
    Q, _ = np.linalg.qr(rng.normal(size=(len(values), 3, 3)))
    return np.einsum("nij,nj,nkj->nik", Q, values, Q)


def test_smallest_eigenvalue3_is_eigvalshs_to_rounding():
    """flat.smallest_eigenvalue3 (the proven intervals' first guess) against numpy's eigvalsh,
    within a few units of the last place of the matrix's norm: on random matrices, on the two
    least eigenvalues nearly or exactly equal (where the closed form alone loses half the digits),
    the two largest, all three, badly conditioned ones, multiples of the identity, scales near
    overflow and underflow, and non-finite entries (read as 0)."""
    rng = np.random.default_rng(seed("smallest eigenvalue"))
    n = 4000
    base = rng.normal(size=(n, 1)) * np.ones((1, 3))
    cases = [rng.normal(size=(n, 3, 3))]
    cases[0] = cases[0] + cases[0].transpose(0, 2, 1)
    for d in (1e-2, 1e-4, 1e-8, 1e-12, 0.0):
        near = rng.normal(size=n) * d
        cases.append(_rotated(rng, base + np.stack([np.zeros(n), near, np.full(n, 3.0)], axis=1)))  # least pair
        cases.append(_rotated(rng, base + np.stack([np.full(n, -3.0), near, np.zeros(n)], axis=1)))  # top pair
        cases.append(_rotated(rng, 5 + d * rng.normal(size=(n, 3))))  # all three
    cases.append(_rotated(rng, np.stack([1e-9 * rng.random(n), rng.random(n), 1 + rng.random(n)], axis=1)))
    cases.append(rng.normal(size=(n, 1, 1)) * np.eye(3))
    M = np.concatenate(cases)
    M = M * 10.0 ** rng.uniform(-150, 150, size=(len(M), 1, 1))  # p^3 over- and underflows at the ends
    entries = np.stack([M[:, a, b] for a, b in PAIRS])
    entries[:, :50] = np.where(rng.random((6, 50)) < 0.3, np.nan, entries[:, :50])
    entries[:, 50:100] = np.where(rng.random((6, 50)) < 0.3, np.inf, entries[:, 50:100])
    entries[0, 100:110] = np.inf  # several flawed entries, still one matrix each
    read = np.where(np.isfinite(entries), entries, 0.0)
    matrices = read[[0, 1, 2, 1, 3, 4, 2, 4, 5]].T.reshape(-1, 3, 3)
    expected = np.linalg.eigvalsh(matrices)[:, 0]
    got = flat_tracks.smallest_eigenvalue3(entries)
    norm = np.sqrt((matrices * matrices).sum(axis=(1, 2)))
    assert np.all(np.abs(got - expected) <= 64 * np.finfo(float).eps * norm)
    assert np.array_equal(flat_tracks.smallest_eigenvalue3(np.zeros((6, 3))), np.zeros(3))


def test_a_bound_at_a_given_radius_is_the_ladders_and_needs_a_radius_that_encloses(dinosaur):
    """bounds_at (what a checker of a claimed radius computes) gives the ladder's bound at the
    ladder's radius, none at a radius too small to enclose the region or not a positive number."""
    cameras, tracks = dinosaur
    flat, x, _, _ = solve(cameras, tracks)
    lower, radius, cost = convexity_bounds(flat, x)
    proven = np.isfinite(lower)
    again, cost_again = bounds_at(flat, x, np.where(proven, radius, 1.0))
    assert np.array_equal(again[proven], lower[proven]) and np.array_equal(cost_again, cost)
    assert np.all(np.isneginf(bounds_at(flat, x, np.where(proven, radius * 1e-6, 1.0))[0][proven]))
    for bad in (0.0, -1.0, np.nan, np.inf):
        assert np.all(np.isneginf(bounds_at(flat, x, np.full(len(x), bad))[0]))


def test_the_convexity_paths_results_hold_against_the_branch_and_bound(dinosaur):
    """convexity_path.certify_tracks: each result it certifies has the cost its point and
    residuals give, a lower bound below the branch and bound's certified optimum and within the
    tolerance of its cost; it certifies nearly every Dinosaur track."""
    from geocert.core.geometry import norm_cost, normalised_cameras, reprojection_residuals
    from geocert.formulations.fractional.convexity_path import certify_tracks

    cameras, tracks = dinosaur
    options = TriangulationOptions(norm="L2L2", rel_gap=1e-3)
    ours = certify_tracks(normalised_cameras(cameras), tracks, options)
    theirs = triangulate_many(cameras, tracks, options)
    assert sum(r is not None for r in ours) >= 0.99 * len(tracks)
    for (views, points), mine, other in zip(tracks, ours, theirs):
        if mine is None:
            continue
        residuals = reprojection_residuals(cameras[views], np.append(mine.point, 1.0), points)
        assert np.allclose(mine.residuals, residuals, rtol=0, atol=1e-9)
        assert abs(mine.cost - norm_cost(residuals, "L2L2")) <= 1e-9 * mine.cost  # the verifier's OBJECTIVE_TOLERANCE
        assert mine.certified and mine.status == "optimal" and mine.nodes == 0
        assert mine.lower_bound <= other.cost and mine.lower_bound <= mine.cost
        assert mine.cost <= other.cost * (1 + 1e-9)
        assert mine.gap <= max(options.abs_gap, options.rel_gap * mine.cost)


@pytest.mark.parametrize("noise", [(1.0,), (30.0, 300.0)])
def test_the_convexity_path_certifies_nothing_the_branch_and_bound_refutes(noise):
    """Noisy tracks of 2 to 4 views (several local minima at 30-300 px): every lower bound the
    path certifies lies below the branch and bound's certified optimum of the track, and a
    track it leaves is left whole (None)."""
    from geocert.core.geometry import normalised_cameras
    from geocert.formulations.fractional.convexity_path import certify_tracks

    rng = np.random.default_rng(seed("path", str(noise)))
    cams, tracks = scene(rng, 120, (2, 4), noise, cameras=6)
    options = TriangulationOptions(norm="L2L2", rel_gap=1e-3)
    ours = certify_tracks(normalised_cameras(cams), tracks, options)
    theirs = triangulate_many(cams, tracks, options)
    checked = 0
    for mine, other in zip(ours, theirs):
        if mine is not None and other.certified:
            assert mine.lower_bound <= other.cost * (1 + 1e-12)
            checked += 1
    assert checked > 10


def test_every_bound_the_path_claims_is_one_a_checker_proves_track_by_track(dinosaur):
    """convexity.track_bound, one track at a time from the claim's point and radius (as a
    verifier computes it), proves at least the lower bound the batched path claimed, for every
    certified Dinosaur track (the solver's doubled allowances absorb the sums' last bits)."""
    from geocert.core.geometry import normalised_cameras
    from geocert.formulations.fractional.convexity import track_bound
    from geocert.formulations.fractional.convexity_path import certify_tracks

    cameras, tracks = dinosaur
    cameras = normalised_cameras(cameras)
    results = certify_tracks(cameras, tracks, TriangulationOptions(norm="L2L2", certificate="full"))
    checked = 0
    for (views, points), result in zip(tracks, results):
        if result is None:
            continue
        radius = result.certificate.proof["radius"]
        assert track_bound(cameras[views], points, result.point, radius) >= result.lower_bound
        checked += 1
    assert checked >= 0.99 * len(tracks)


def test_a_track_within_abs_gap_of_zero_is_left_to_the_trivial_bound():
    """Exact observations: the cost is within abs_gap of 0, which the trivial bound certifies
    (the search's first step); the convexity path leaves such a track."""
    from geocert.core.geometry import normalised_cameras
    from geocert.formulations.fractional.convexity_path import certify_tracks

    rng = np.random.default_rng(seed("exact"))
    cams = random_cameras(rng, 6)
    tracks = []
    for noise in [0.0] * 20 + [1.0] * 20:
        chosen = sorted(rng.choice(6, size=3, replace=False).tolist())
        tracks.append((chosen, noisy_track(rng, cams[chosen], noise_px=noise)[1]))
    results = certify_tracks(normalised_cameras(cams), tracks, TriangulationOptions(norm="L2L2"))
    assert all(r is None for r in results[:20])
    assert all(r is not None for r in results[20:])


def test_numbers_outside_the_range_prove_nothing():
    """The bound's round-off is counted for numbers 0 or within 2^+-128 (no product but a
    cancelled difference's underflows): a subnormal or huge number in the data, the point or
    the radius proves nothing, where the same track in range is proven."""
    rng = np.random.default_rng(seed("convexity range"))
    cams, tracks = scene(rng, 1, (3, 3), (1.0,), cameras=3)
    (views, points), = tracks
    cams[views[0], 0, 1] = 0.0  # an entry that a subnormal can take the place of
    flat, x, _, _ = solve(cams, tracks)
    _, radius, _ = convexity_bounds(flat, x)
    cameras = cams[views]
    assert np.isfinite(track_bound(cameras, points, x[0], radius[0]))
    subnormal = cameras.copy()
    subnormal[0, 0, 1] = 5e-324
    far = x[0].copy()
    far[0] = 1e40
    for args in ((subnormal, points, x[0], radius[0]), (cameras, points * 1e39, x[0], radius[0]),
                 (cameras, points, far, radius[0]), (cameras, points, x[0], 5e-324),
                 (cameras, points, x[0], 1e40)):
        assert track_bound(*args) == -np.inf
        assert outside_range(*args) is not None
    assert outside_range(cameras, points, x[0], radius[0]) is None
