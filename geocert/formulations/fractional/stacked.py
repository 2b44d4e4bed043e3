"""The verifier's fast path for triangulation documents: the tracks whose proof has the common
shape (the root region, no tightening round, up to MAX_LEAVES leaves each closed by a dual
vector, no scope limit) checked many at once, their arrays stacked by number of views and
branched functionals (the leaves' relaxations by leaf).

Each check is the per-item check (items.py, proof.py, verify.py) on stacked arrays, with the
same tolerances; the relaxation is rebuilt here with a leading axis over tracks, row for row as
``Relaxation.relaxation`` builds it (tests/verify/test_stacked_verification.py compares the
two). A track any check here refuses, or whose document does not have that shape, is not
reported proven: the verifier then checks it alone, and its report names the failure. So this
path can only ever accept what it has checked; it never decides a refusal.

Why: one track's check is some two hundred small numpy calls, about 3 ms of which the arrays'
arithmetic is a small part; stacked, the calls are shared by every track of a group.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from geocert.core import exact
from geocert.core.certificates import BOUND_TOLERANCE, OBJECTIVE_TOLERANCE, TERMS_ROUNDING, residual_rounding
from geocert.core.bnb import Box
from geocert.core.cones import ConeSpec, _project_rows, rounding_counted, stacked_rounding_margin, subnormal
from geocert.core.coverage import uncovered_part
from geocert.core.geometry import cost_roundings, lengths, norm_terms, normalised_cameras, outside_squares
from geocert.core.strict import Invalid, charge, dual_vector, numbers
from geocert.formulations.fractional.charts import reference_work
from geocert.formulations.fractional.convexity import verify_sublevel
from geocert.formulations.fractional.proof import (SCALE_RANGE, _sample_steps, allowance, raw_sizes, stated_root_agrees,
                                             track_uncertainty)

D = 3  # a track's program has 3 variables
CHECKS = ("data", "claim", "objective", "scope", "program", "root_region", "tightening", "coverage",
          "leaf_bounds", "lower_bound", "gap")  # what verify_item reports for such a track
MAX_ENTRIES = 4_000_000  # floats of one chunk's relaxation matrices (32 MB)
MAX_LEAVES = 64  # leaves and proofs of one track on this path (more: checked alone)
# The members of the records this path reads (proof.verify_search's, without caps or tightening).
PROOF_MEMBERS = frozenset(("type", "scale", "root", "tightening", "search_box", "proofs", "leaves"))
ROOT_MEMBERS = frozenset(("gamma", "functionals", "claim", "bounds", "duals"))
LEAF_PROOF_MEMBERS = frozenset(("box", "upper_bound", "kind", "z", "bound"))


_NUMBERS = frozenset((int, float))


def _flat(value, sizes: tuple[int, ...], out: list) -> bool:
    """Append nested lists of numbers (ints or floats; their values are checked in bulk by
    _check_group) of exactly these sizes to ``out``; False if not so."""
    if type(value) is not list or len(value) != sizes[0]:
        return False
    if len(sizes) == 1:
        if not _NUMBERS.issuperset(map(type, value)):
            return False
        out.extend(value)
        return True
    return all(_flat(row, sizes[1:], out) for row in value)


def _dual(text, rows: int) -> np.ndarray | None:
    """strict.dual_vector's reading (base64 of float64, ``rows`` finite entries), None where it
    refuses."""
    try:
        return dual_vector(text, rows)
    except Invalid:
        return None


class _Track:
    """One track's claim and data read strictly, in the common proof's shape."""

    __slots__ = ("position", "views", "k", "values", "root_duals", "proof_values", "proof_duals", "leaf_values",
                 "leaf_proofs")


def _read(position: int, claim: dict, tracks: list, n_cameras: int, max_views: int) -> _Track | None:
    if claim.get("status") != "optimal" or claim.get("at_infinity") is not False:
        return None
    proof = claim.get("proof")
    if not isinstance(proof, dict) or proof.get("type") != "branch_and_bound" or "relaxation" in proof:
        return None  # (the per-item path reads a proof whose relaxation is not the envelope of t / s)
    root, proofs, leaves = proof.get("root"), proof.get("proofs"), proof.get("leaves")
    if (not isinstance(root, dict) or proof.get("tightening") != [] or not isinstance(proofs, list)
            or not 1 <= len(proofs) <= MAX_LEAVES or not isinstance(leaves, list)
            or not 1 <= len(leaves) <= MAX_LEAVES):
        return None
    # Exactly the members the per-item path's records take (strict.record), no caps: any other
    # record is checked alone, whose reading names what it refuses.
    if not (set(proof) - {"sublevel"} == PROOF_MEMBERS and set(root) == ROOT_MEMBERS):
        return None
    if not all(isinstance(p, dict) and p.get("kind") == "dual" and set(p) == LEAF_PROOF_MEMBERS for p in proofs):
        return None
    if not all(isinstance(leaf, list) and len(leaf) == 3 and type(leaf[2]) is int and 0 <= leaf[2] < len(proofs)
               for leaf in leaves):
        return None
    search_box = proof.get("search_box")
    k = len(search_box[0]) if isinstance(search_box, list) and search_box and isinstance(search_box[0], list) else 0
    if not 0 < k <= D or position >= len(tracks) or not isinstance(tracks[position], dict):
        return None
    track = tracks[position]
    views = track.get("views")
    if (not isinstance(views, list) or not 2 <= len(views) <= max_views
            or not all(type(v) is int and 0 <= v < n_cameras for v in views) or len(set(views)) != len(views)):
        return None
    n = len(views)
    values: list = []
    if not (_flat([claim.get("cost"), claim.get("gap"), claim.get("lower_bound"), proof.get("scale"),
                   root.get("gamma")], (5,), values)
            and _flat(claim.get("point"), (3,), values) and _flat(root.get("functionals"), (D, D), values)
            and _flat(root.get("claim"), (2, D), values) and _flat(root.get("bounds"), (2, D), values)
            and _flat(search_box, (2, k), values) and _flat(track.get("points"), (n, 2), values)):
        return None
    proof_values: list = []
    if not all(_flat(p.get("box"), (2, k), proof_values) and _flat([p.get("upper_bound"), p.get("bound")], (2,),
                                                                    proof_values) for p in proofs):
        return None
    leaf_values: list = []
    if not all(_flat(leaf[:2], (2, k), leaf_values) for leaf in leaves):
        return None
    duals = root.get("duals")
    if not isinstance(duals, list) or len(duals) != 2 * D:
        return None
    rows = 1 + 3 * n
    root_duals = [_dual(text, rows) for text in duals]
    if any(z is None for z in root_duals):
        return None
    result = _Track()
    result.position, result.views, result.k = position, views, k
    result.values, result.root_duals = values, root_duals
    result.proof_values, result.leaf_values = proof_values, leaf_values
    result.proof_duals = [p.get("z") for p in proofs]  # decoded once their relaxation's size is known
    result.leaf_proofs = [leaf[2] for leaf in leaves]
    return result


def proven_tracks(data: dict, options: dict, claims: list, max_views: int) -> set[int]:
    """The positions of the certified claims this path proves (see the module's docstring)."""
    if options["max_residual"] is not None or not isinstance(data, dict):
        return set()
    cameras = normalised_cameras(numbers(data.get("cameras"), "data/cameras", (None, 3, 4), "data"))
    tracks = data.get("tracks")
    if not isinstance(tracks, list):
        return set()
    groups: dict[tuple[int, int], list[_Track]] = defaultdict(list)
    for position, claim in enumerate(claims):
        # The index an int (the per-item path reads data/tracks[index]: 1.0 == 1, but is no index).
        if (isinstance(claim, dict) and claim.get("certified") is True and type(claim.get("index")) is int
                and claim["index"] == position):
            track = _read(position, claim, tracks, len(cameras), max_views)
            if track is not None:
                groups[(len(track.views), track.k)].append(track)
    proven: set[int] = set()
    for (n, k), members in groups.items():
        rows, cols = _relaxation_size(n, k, options["norm"])
        # A track whose own relaxations (one per leaf proof) exceed a chunk's size, past about 240 to
        # 300 views for one proof, is left to the per-item path (sparse relaxations, linear memory).
        members = [t for t in members if len(t.proof_duals) * rows * cols <= MAX_ENTRIES]
        for chunk in _chunks(members, MAX_ENTRIES // (rows * cols)):
            try:
                with np.errstate(all="ignore"):  # a NaN fails every check below (each asks a comparison to hold)
                    ok = _check_group(cameras, chunk, n, k, options)
            except Exception:  # e.g. a singular chart: the per-item path checks these, and says why
                continue
            proven.update(t.position for t, good in zip(chunk, ok) if good)
    return {i for i in proven if _interval_holds(cameras, tracks[i], claims[i], options["norm"])}


def _interval_holds(cameras: np.ndarray, track: dict, claim: dict, norm: str) -> bool:
    """Whether a proven claim's proven interval, if it states one, is proven (checked alone,
    as the per-item path checks it; one that is not leaves the claim to that path)."""
    if "sublevel" not in claim["proof"]:
        return True
    try:
        verify_sublevel(cameras[track["views"]], np.asarray(track["points"], dtype=float), claim["proof"]["sublevel"],
                        np.append(np.asarray(claim["point"], dtype=float), 1.0), norm)
    except Invalid:
        return False
    return True


def _chunks(members: list[_Track], proofs: int):
    """Consecutive runs of tracks with at most ``proofs`` leaf proofs between them (at least one
    track each): what bounds the memory of one stacked relaxation."""
    start, count = 0, 0
    for i, track in enumerate(members):
        if count and count + len(track.proof_duals) > proofs:
            yield members[start:i]
            start, count = i, 0
        count += len(track.proof_duals)
    if start < len(members):
        yield members[start:]


def _check_group(all_cameras: np.ndarray, members: list[_Track], n: int, k: int, options: dict) -> np.ndarray:
    """Every check of the common proof for ``members`` (n views, k branched functionals each):
    a boolean per track, true when every check passes."""
    norm = options["norm"]
    G = len(members)
    try:
        values = np.array([t.values for t in members], dtype=float)  # (G, fields)
    except OverflowError:  # an int past the float range (the per-item reader names it)
        return np.zeros(G, dtype=bool)
    # What geometry.is_number asks of each number (and a little more: no float beyond 2^1023).
    ok = np.all(np.abs(values) < 2.0**1023, axis=1)
    values = np.where(ok[:, None], values, 1.0)
    columns = iter(np.split(values, np.cumsum([1, 1, 1, 1, 1, 3, 9, 6, 6, 2 * k]), axis=1))
    cost, gap, lower_claimed, scale, gamma = (next(columns)[:, 0] for _ in range(5))
    point = next(columns)
    F = next(columns).reshape(G, D, D)
    claim_box, bounds, search_box = (next(columns).reshape(G, 2, -1) for _ in range(3))
    points = next(columns).reshape(G, n, 2)
    cams = all_cameras[np.array([t.views for t in members])]  # (G, n, 3, 4)

    # The claim's numbers (verify_arrays).
    ok &= (0 <= gap) & (lower_claimed <= cost) & (
        np.abs((cost - gap) - lower_claimed) <= 1e-12 * np.maximum(np.abs(cost), np.abs(lower_claimed)))

    # The chart (charts.Chart.build).
    num, den, T, reference, charted = chart_arrays(cams, points)
    ok &= charted

    # The solution's cost and depths from the raw data (_check_residual_claim).
    X = np.concatenate([point, np.ones((G, 1))], axis=1)
    proj = np.einsum("gnij,gj->gni", cams, X)
    image = proj[..., :2] / proj[..., 2:3]
    residuals = image - points
    ok &= np.all(proj[..., 2] > 0, axis=1)
    recomputed = norm_terms(residuals, norm).sum(axis=1)
    rounding = residual_rounding(image, points)
    slack = cost_roundings(residuals, rounding, norm)
    with np.errstate(all="ignore"):
        spread = cost_roundings(residuals, track_uncertainty(cams, X), norm)
    # where the floats' rounding could move the cost, the residuals computed exactly, as the
    # per-item check reads them (exact.needs_exact)
    for g in np.flatnonzero(ok & ~(spread <= exact.FLOAT_SHARE * OBJECTIVE_TOLERANCE * np.abs(recomputed))):
        stated = -exact.residuals(cams[g], X[g], points[g])
        recomputed[g] = exact.cost(stated, norm)
        slack[g] = exact.slack(stated, norm)
    ok &= np.abs(recomputed - cost) <= OBJECTIVE_TOLERANCE * np.abs(recomputed) + slack
    tolerance = np.maximum(options["abs_gap"], options["rel_gap"] * np.abs(cost))
    ok &= (recomputed + slack) - lower_claimed <= tolerance * (1 + 1e-12)  # the gap, from the data's cost
    ok &= spread <= np.maximum(options["abs_gap"], options["rel_gap"] * np.abs(cost))

    # The program at the claimed scale (verify_search) and its agreement with the data.
    ok &= (SCALE_RANGE[0] <= scale) & (scale <= SCALE_RANGE[1])
    num = num * scale[:, None, None, None]
    unit = scale**2 if norm == "L2L2" else scale
    cap = np.maximum(0.0, lower_claimed * unit * (1 - BOUND_TOLERANCE))
    w = np.linalg.solve(T, X[..., None])[..., 0]
    ok &= w[:, 3] > 0
    v0 = w[:, :3] / np.where(w[:, 3] > 0, w[:, 3], 1.0)[:, None]
    agree, allowed = program_agrees(cams, points, num, den, T, scale, v0, reference)
    ok &= agree

    # The root region (proof._check_root).
    k_ok = np.linalg.cond(F) <= 1e6
    ok &= k_ok
    F = np.where(k_ok[:, None, None], F, np.eye(D))
    needed = np.sqrt(cap) if norm == "L2L2" else cap
    ok &= gamma >= needed
    linear = T[:, 3][:, None, :]  # (G, 1, 4): the last homogeneous coordinate >= 0
    ok &= _root_holds(num, den, linear, gamma, F, claim_box, bounds, v0, members, n)

    # The searched box, the leaves and their proofs (tightening, coverage, leaf_bounds).
    box_lo, box_hi = bounds[:, 0, :k], bounds[:, 1, :k]
    ok &= np.all(search_box[:, 0] <= box_lo, axis=1) & np.all(search_box[:, 1] >= box_hi, axis=1)
    proven = _leaves_hold(members, num, den, linear, F, k, bounds, search_box, cap, norm, reference, ok)
    # The bound against the claim, and the gap (verify_arrays): the program's bound lowered by
    # its distance from the data's problem (proof.program_discount).
    with np.errstate(invalid="ignore"):
        discount = cost_roundings(residuals, allowed, norm) if rounding_counted() else 0.0
    proven = proven / unit - np.where(np.isfinite(discount), discount, np.inf)
    ok &= proven >= lower_claimed - BOUND_TOLERANCE * np.abs(lower_claimed)
    tolerance = np.maximum(options["abs_gap"], options["rel_gap"] * np.abs(cost))
    ok &= gap <= tolerance * (1 + 1e-12)
    return ok


def chart_arrays(cams: np.ndarray, points: np.ndarray):
    """charts.Chart.build for every track of a group: (num, den, T, reference, ok). ``ok`` is
    false where this path does not build the chart (a centre at infinity, or a depth row that
    may be parallel to the reference's: the per-item path decides those)."""
    G, n = cams.shape[:2]
    charge(reference_work(n, G), "choosing the tracks' chart references (each centre seen by every view)")
    centres = np.linalg.svd(cams)[2][..., -1, :]
    centres = centres * np.where(centres[..., 3:4] < 0, -1.0, 1.0)
    # The reference: the camera whose centre projects farthest from the other views' observations.
    proj = np.einsum("gjab,grb->grja", cams, centres)
    depth = proj[..., 2]
    safe = np.where(depth > 1e-12 * lengths(proj), depth, np.nan)
    distance = lengths(proj[..., :2] / safe[..., None] - points[:, None])
    distance = np.where(np.isnan(distance), np.inf, distance)
    distance[:, np.arange(n), np.arange(n)] = np.inf
    reference = np.argmax(distance.min(axis=2), axis=1)
    # The frame: every centre finite here.
    ok = np.all(np.abs(centres[..., 3]) > 1e-9 * lengths(centres), axis=1)
    euclid = centres[..., :3] / np.where(ok[:, None], centres[..., 3], 1.0)[..., None]
    middle = euclid.sum(axis=1) / n
    # Charts whose spread or framed cameras are read at a power of two by Chart.build (a world
    # unit whose lengths' squares underflow or overflow: charts._spread_shift, charts._near_one)
    # are left to it, as is every track this path does not chart.
    ok &= ~outside_squares(np.max(np.abs(euclid - middle[:, None]), axis=(1, 2)))
    spread = lengths(euclid - middle[:, None]).sum(axis=1) / n
    spread = np.where(spread > 0, spread, 1.0)
    H = np.tile(np.eye(4), (G, 1, 1))
    H[:, :3, :3] *= spread[:, None, None]
    H[:, :3, 3] = middle
    framed = cams @ H[:, None]
    ok &= ~np.any(outside_squares(np.max(np.abs(framed), axis=(2, 3))), axis=1)
    framed = framed / lengths(framed[:, :, 2, :3])[..., None, None]
    every = np.arange(G)
    depth_row = framed[every, reference, 2]
    vt = np.linalg.svd(depth_row[:, None, :])[2]
    T = np.empty((G, 4, 4))
    T[:, :, :3] = vt[:, 1:].transpose(0, 2, 1)
    T[:, :, 3] = depth_row / np.einsum("gi,gi->g", depth_row, depth_row)[:, None]
    shifted = framed.copy()
    shifted[:, :, 0] -= points[..., 0:1] * framed[:, :, 2]
    shifted[:, :, 1] -= points[..., 1:2] * framed[:, :, 2]
    M = shifted @ T[:, None]
    grad, row = lengths(M[..., 2, :3]), lengths(M[..., 2, :])
    # Exact views: only the reference here (a float test rules out any other parallel depth row).
    rows = cams[:, :, 2]
    d = rows[every, reference]
    minors = rows[..., :, None] * d[:, None, None, :] - rows[..., None, :] * d[:, None, :, None]
    size = lengths(rows) * lengths(d)[:, None]
    maybe = np.all(np.abs(minors) <= 1e-12 * size[..., None, None], axis=(2, 3))
    exact = np.zeros((G, n), dtype=bool)
    exact[every, reference] = True
    ok &= ~np.any(maybe & ~exact, axis=1)
    scale = np.where(exact, M[..., 2, 3], np.where(grad > 1e-9 * row, grad, row))
    ok &= ~np.any(exact & (scale <= 0), axis=1)
    scale = np.where(scale == 0, 1.0, np.abs(scale))
    M = M / scale[..., None, None]
    den = M[..., 2, :].copy()
    den[exact] = np.array([0.0, 0.0, 0.0, 1.0])
    return M[..., :2, :].copy(), den, H @ T, reference, ok


def program_agrees(cams, points, num, den, T, scale, v0, reference, strictness: float = 1.0
                   ) -> tuple[np.ndarray, np.ndarray]:
    """proof.check_program for every track: the program's residuals and depth signs are the
    raw data's at the solution and at eight fixed points around it (``strictness`` as there);
    and the allowance at the solution (proof.allowance, (G, n, 2))."""
    steps = np.array(_sample_steps(D))
    samples = np.concatenate([v0[:, None], v0[:, None] + steps[None] * (1 + np.abs(v0))[:, None]], axis=1)
    V = np.concatenate([samples, np.ones(samples.shape[:2] + (1,))], axis=2)  # (G, 9, 4)
    solutions = np.einsum("gsk,gjk->gsj", V, T)
    proj = np.einsum("gNij,gsj->gsNi", cams, solutions)
    numerators = proj[..., :2] - points[:, None] * proj[..., 2:3]
    depths = proj[..., 2]
    numerator_size, depth_size = raw_sizes(cams, points, solutions)
    ours = np.einsum("gNmk,gsk->gsNm", num, V) / scale[:, None, None, None]
    ours_depth = np.einsum("gsk,gNk->gsN", V, den)
    clear = np.abs(depths) > 1e-6 * depth_size
    safe_depths, safe_ours_depth = np.where(clear, depths, 1.0), np.where(clear, ours_depth, 1.0)
    theirs = np.where(clear[..., None], numerators / safe_depths[..., None], 0.0)
    ours = np.where(clear[..., None], ours / safe_ours_depth[..., None], 0.0)
    largest = np.max(np.abs(theirs), axis=(2, 3), keepdims=True)
    tolerance = 1e-9 * (1 + largest) + 1e-6 * np.abs(theirs) \
        + TERMS_ROUNDING * (numerator_size + np.abs(theirs) * depth_size[..., None]) / np.abs(safe_depths)[..., None]
    agree = np.all(np.abs(ours - theirs) <= strictness * tolerance, axis=(1, 2, 3))
    exact = np.zeros(den.shape[:2], dtype=bool)
    exact[np.arange(len(den)), reference] = True
    varying = ~exact[:, None] & clear
    relative = np.sign(ours_depth) * np.sign(depths)
    allowed = allowance(ours[:, 0], theirs[:, 0], numerator_size[:, 0], depth_size[:, 0], depths[:, 0], clear[:, 0])
    return agree & ~np.any(varying & ~(relative > 0), axis=(1, 2)), allowed


def safe_bounds(Q, A, b, Z, cones: ConeSpec, lower, upper, transform) -> np.ndarray:
    """cones.safe_lower_bounds with a leading axis over tracks: Q (G, p, cols), A (G, rows, cols),
    b (G, rows), Z (G, p, rows), lower and upper (G, cols), transform (G, d, d); each bound less
    its rounding (cones.stacked_rounding_margin), subnormal entries of Z read as 0."""
    G, p, rows = Z.shape
    Z = Z.copy()
    Z[subnormal(Z)] = 0.0
    with np.errstate(over="ignore", invalid="ignore"):
        Z = _project_rows(Z.reshape(G * p, rows), cones).reshape(G, p, rows)
        residual = Q + np.einsum("gpr,grc->gpc", Z, A)
        d = transform.shape[1]
        residual = np.concatenate([np.einsum("gpc,gcd->gpd", residual[..., :d], transform), residual[..., d:]], axis=2)
        terms = np.minimum(residual * lower[:, None], residual * upper[:, None])
        terms[residual == 0] = 0.0
        bounds = -np.einsum("gpr,gr->gp", Z, b) + terms.sum(axis=2)
        reach = np.maximum(np.abs(lower), np.abs(upper))
        bounds = bounds - stacked_rounding_margin(np.abs(np.broadcast_to(Q, residual.shape)), np.abs(A), np.abs(b), Z,
                                                  reach, np.abs(transform), terms)
    return np.where(np.isfinite(bounds), bounds, -np.inf)


def _root_holds(num, den, linear, gamma, F, claim_box, bounds, v0, members, n) -> np.ndarray:
    """proof._check_root for every track."""
    G = len(num)
    per_observation = np.concatenate([gamma[:, None, None, None] * den[:, :, None, :], num], axis=2)
    E = np.concatenate([linear, per_observation.reshape(G, 3 * n, 4)], axis=1)
    A, b = -E[..., :-1], E[..., -1]
    claim_lo, claim_hi = claim_box[:, 0], claim_box[:, 1]
    V = np.concatenate([v0, np.ones((G, 1))], axis=1)
    numerators = np.einsum("gNmk,gk->gNm", num, V)
    depths = np.einsum("gNk,gk->gN", den, V)
    linear_value = np.einsum("gk,gk->g", linear[:, 0], V)
    inside = (np.all(lengths(numerators) <= gamma[:, None] * depths, axis=1)
              & (linear_value >= -1e-12 * np.einsum("gk,gk->g", np.abs(linear[:, 0]), np.abs(V))))
    y = np.einsum("gij,gj->gi", F, v0)
    margin = 1e-9 * (1 + np.abs(claim_lo) + np.abs(claim_hi))
    inside &= np.all(claim_lo + margin < y, axis=1) & np.all(y < claim_hi - margin, axis=1)
    Q = np.empty((G, 2 * D, D))
    Q[:, 0::2], Q[:, 1::2] = F, -F
    Z = np.array([t.root_duals for t in members])  # finite: read by strict.dual_vector
    proven = safe_bounds(Q, A, b, Z, ConeSpec(nonneg=1, soc=(3,) * n), claim_lo, claim_hi, np.linalg.inv(F))
    low, high = proven[:, 0::2], -proven[:, 1::2]
    return (inside & np.all((claim_lo < low) & (low <= high) & (high < claim_hi), axis=1)
            & np.all((bounds[:, 0] <= low) & (bounds[:, 1] >= high), axis=1)
            & np.all(stated_root_agrees(claim_lo, claim_hi, bounds[:, 0], bounds[:, 1], low, high), axis=1))


def _relaxation_size(n: int, k: int, norm: str) -> tuple[int, int]:
    nE, m = n - 1, 2
    rows = 2 * k + 1 + 5 * nE + 3 * nE + {"L2L2": (m + 2) * n + (m + 1) * n, "L2L1": 2 * (m + 1) * n,
                                          "L1L1": (2 * m + 2) * n}[norm]
    return rows, D + 3 * nE + 1 + (m * n if norm == "L1L1" else 0)


def _leaves_hold(members, num, den, linear, F, k, bounds, search_box, cap, norm, reference, ok) -> np.ndarray:
    """proof._check_leaf_proofs and the coverage check for every track: each proof's bound
    recomputed (each must hold), each leaf inside its proof's box, the leaves covering the
    searched box; the track's bound is its leaves' smallest (-inf where a check fails)."""
    counts = np.array([len(t.proof_duals) for t in members])
    owner = np.repeat(np.arange(len(members)), counts)  # the track of each proof
    proofs = np.array([v for t in members for v in t.proof_values], dtype=float).reshape(len(owner), 2 * k + 2)
    proof_box, ub, claimed = proofs[:, :2 * k].reshape(-1, 2, k), proofs[:, 2 * k], proofs[:, 2 * k + 1]
    good = (np.all(np.abs(proofs) < 2.0**1023, axis=1) & (ub >= cap[owner])) & ok[owner]
    E, cones, q, lower, upper, transform, built = leaf_relaxations(
        num[owner], den[owner], linear[owner], F[owner], k, bounds[owner], proof_box, ub, norm, reference[owner])
    R, rows, cols = len(E), E.shape[1], E.shape[2] - 1
    good &= built
    Z = np.zeros((R, 1, rows))
    for i, text in enumerate(z for t in members for z in t.proof_duals):
        z = _dual(text, rows)
        if z is None:
            good[i] = False
        else:
            Z[i, 0] = z
    bound = safe_bounds(np.broadcast_to(q, (R, 1, cols)), -E[..., :cols], E[..., cols], Z, cones, lower, upper,
                         transform)[:, 0]
    good &= bound >= claimed - BOUND_TOLERANCE * np.abs(claimed)
    # Every proof of a track must hold, whether a leaf names it or not (as the per-item check asks).
    held = np.bincount(owner, weights=good, minlength=len(members)) == counts
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])  # each track's first proof
    leaves = np.array([v for t in members for v in t.leaf_values], dtype=float)
    leaf_count = np.array([len(t.leaf_proofs) for t in members])
    leaf_owner = np.repeat(np.arange(len(members)), leaf_count)
    leaves = leaves.reshape(len(leaf_owner), 2, k)
    named = first[leaf_owner] + np.array([i for t in members for i in t.leaf_proofs])
    inside = (np.all(np.abs(leaves) < 2.0**1023, axis=(1, 2)) & np.all(proof_box[named, 0] <= leaves[:, 0], axis=1)
              & np.all(proof_box[named, 1] >= leaves[:, 1], axis=1))
    held &= np.bincount(leaf_owner, weights=inside, minlength=len(members)) == leaf_count
    result = np.full(len(members), np.inf)
    np.minimum.at(result, leaf_owner, bound[named])  # a track's bound: its leaves' smallest
    # Coverage: one leaf covers a box of positive width by containing it; several are checked as
    # the per-item path checks them (core.coverage).
    single = leaf_count == 1
    lone = np.concatenate([[0], np.cumsum(leaf_count)[:-1]])  # each track's first leaf
    covers = (np.all(search_box[:, 1] > search_box[:, 0], axis=1)
              & np.all(leaves[lone, 0] <= search_box[:, 0], axis=1) & np.all(leaves[lone, 1] >= search_box[:, 1], axis=1))
    for i in np.flatnonzero(~single & held & ok):
        mine = leaf_owner == i
        covers[i] = uncovered_part(Box(search_box[i, 0], search_box[i, 1]), leaves[mine, 0], leaves[mine, 1]) is None
    return np.where(held & covers, result, -np.inf)


def leaf_relaxations(num, den, linear, F, k, bounds, proof_box, ub, norm, reference):
    """Relaxation.conic_data of each track's proof box for points costing at most ``ub``,
    rebuilt with a leading axis over tracks, row for row (the reference the one exact view;
    no scope limit): (E, cones, q, lower, upper, transform, built), where E = [-A | b] and
    ``built`` is false where no point of the box has every depth positive."""
    G, n = den.shape[:2]
    nE, m = n - 1, 2
    every = np.arange(G)[:, None]
    exact_index = reference  # the one exact view
    order = np.argsort(np.arange(n)[None, :] == exact_index[:, None], axis=1, kind="stable")  # env, then exact
    env = order[:, :nE]
    transform = np.linalg.inv(F)
    depth_y = np.einsum("gNk,gkj->gNj", den[every, env, :D], transform)
    coef, coef_c = depth_y[..., :k], depth_y[..., k:]
    offset = den[every, env, D]
    box_lo, box_hi = proof_box[:, 0], proof_box[:, 1]
    comp_lo, comp_hi = bounds[:, 0, k:], bounds[:, 1, k:]
    # Relaxation.depth_range, rounded outwards.
    low, high, size = offset.copy(), offset.copy(), np.abs(offset)
    ranges = [(coef, box_lo, box_hi)] + ([(coef_c, comp_lo, comp_hi)] if k < D else [])
    for c, lo, hi in ranges:
        pos, neg = np.clip(c, 0, None), np.clip(c, None, 0)
        low = low + (np.einsum("gNj,gj->gN", pos, lo) + np.einsum("gNj,gj->gN", neg, hi))
        high = high + (np.einsum("gNj,gj->gN", pos, hi) + np.einsum("gNj,gj->gN", neg, lo))
        size = size + np.einsum("gNj,gj->gN", np.abs(c), np.maximum(np.abs(lo), np.abs(hi)))
    low, high = low - 1e-12 * size, high + 1e-12 * size
    built = np.all(high > 0, axis=1)  # else no point of the box has every depth positive
    low = np.maximum(low, 0.0)
    high = np.maximum(high, low * (1 + 1e-9) + 1e-15)
    # Relaxation.gammas and relaxation(): no scope limit, a finite cap.
    cost_gamma = np.sqrt(ub) if norm == "L2L2" else ub
    if norm == "L2L2":
        gamma, term = cost_gamma, cost_gamma**2
    elif norm == "L2L1":
        gamma = term = cost_gamma
    else:
        gamma, term = None, cost_gamma
    u = term[:, None] * high
    rows, cols = _relaxation_size(n, k, norm)
    t_idx = D + np.arange(nE)
    w_idx, r_idx = t_idx + nE, t_idx + 2 * nE
    q_idx = D + 3 * nE
    top = np.append(t_idx, q_idx)
    a_idx = (q_idx + 1 + np.arange(m * n)).reshape(n, m) if norm == "L1L1" else None
    obs = np.concatenate([env, exact_index[:, None]], axis=1)
    depth = den[every, obs]  # (G, n, 4)
    numo = num[every, obs]  # (G, n, m, 4)
    g = den[every, env]
    E = np.zeros((G, rows, cols + 1))  # the last column holds the constants c
    r = 0
    B = F[:, :k]
    E[:, r:r + k, :D], E[:, r:r + k, cols] = B, -box_lo
    E[:, r + k:r + 2 * k, :D], E[:, r + k:r + 2 * k, cols] = -B, box_hi
    E[:, r + 2 * k, :D], E[:, r + 2 * k, cols] = linear[:, 0, :D], linear[:, 0, D]
    r += 2 * k + 1
    env_rows = r + 5 * np.arange(nE)  # the envelope of t / s, five rows per view
    lu, hu = low / u, high / u
    E[:, env_rows, w_idx], E[:, env_rows, t_idx] = 1.0, -lu
    E[:, env_rows + 1, t_idx], E[:, env_rows + 1, w_idx] = hu, -1.0
    E[:, env_rows + 2, :D], E[:, env_rows + 2, cols] = g[..., :D], g[..., D] - low
    E[:, env_rows + 2, w_idx], E[:, env_rows + 2, t_idx] = -1.0, lu
    E[:, env_rows + 3, :D], E[:, env_rows + 3, cols] = -g[..., :D], high - g[..., D]
    E[:, env_rows + 3, w_idx], E[:, env_rows + 3, t_idx] = 1.0, -hu
    E[:, env_rows + 4, t_idx], E[:, env_rows + 4, cols] = -1.0, u
    r += 5 * nE
    socs: list[int] = []
    if norm == "L1L1":
        per = 2 * m + 2
        base = r + per * np.arange(n)
        for a in range(m):
            E[:, base + 2 * a, :D], E[:, base + 2 * a, cols] = -numo[:, :, a, :D], -numo[:, :, a, D]
            E[:, base + 2 * a, a_idx[:, a]] = 1.0
            E[:, base + 2 * a + 1, :D], E[:, base + 2 * a + 1, cols] = numo[:, :, a, :D], numo[:, :, a, D]
            E[:, base + 2 * a + 1, a_idx[:, a]] = 1.0
            E[:, base + 2 * m, a_idx[:, a]] = -1.0
            E[:, base + 2 * m + 1, a_idx[:, a]] = -1.0
        E[:, base + 2 * m, top] = 1.0
        E[:, base + 2 * m + 1, :D] = cost_gamma[:, None, None] * depth[..., :D]
        E[:, base + 2 * m + 1, cols] = cost_gamma[:, None] * depth[..., D]
        r += per * n
    n_lin = r
    if norm == "L2L2":
        base = r + (m + 2) * np.arange(n)
        E[:, base, top] = 1.0
        E[:, base, :D], E[:, base, cols] = depth[..., :D], depth[..., D]
        for a in range(m):
            E[:, base + 1 + a, :D], E[:, base + 1 + a, cols] = 2 * numo[:, :, a, :D], 2 * numo[:, :, a, D]
        E[:, base + m + 1, top] = 1.0
        E[:, base + m + 1, :D], E[:, base + m + 1, cols] = -depth[..., :D], -depth[..., D]
        r += (m + 2) * n
        socs += [m + 2] * n
    elif norm == "L2L1":
        base = r + (m + 1) * np.arange(n)
        E[:, base, top] = 1.0
        for a in range(m):
            E[:, base + 1 + a, :D], E[:, base + 1 + a, cols] = numo[:, :, a, :D], numo[:, :, a, D]
        r += (m + 1) * n
        socs += [m + 1] * n
    if gamma is not None:
        base = r + (m + 1) * np.arange(n)
        E[:, base, :D] = gamma[:, None, None] * depth[..., :D]
        E[:, base, cols] = gamma[:, None] * depth[..., D]
        for a in range(m):
            E[:, base + 1 + a, :D], E[:, base + 1 + a, cols] = numo[:, :, a, :D], numo[:, :, a, D]
        r += (m + 1) * n
        socs += [m + 1] * n
    base = r + 3 * np.arange(nE)  # the envelope's cone r (u w) >= t^2, divided by u
    E[:, base, r_idx], E[:, base, w_idx] = 1.0, 1.0 / u
    E[:, base + 1, t_idx] = 2.0 / u
    E[:, base + 2, r_idx], E[:, base + 2, w_idx] = 1.0, -1.0 / u
    socs += [3] * nE
    assert r + 3 * nE == rows
    q = np.zeros(cols)
    q[q_idx], q[r_idx] = 1.0, 1.0
    lower = np.zeros((G, cols))
    upper = np.repeat(np.minimum(ub, term)[:, None], cols, axis=1)
    lower[:, :k], lower[:, k:D] = box_lo, comp_lo
    upper[:, :k], upper[:, k:D] = box_hi, comp_hi
    upper[:, t_idx] = np.minimum(u, high * ub[:, None])
    upper[:, w_idx] = high
    if a_idx is not None:
        upper[:, a_idx] = upper[:, top][:, :, None]
    built = built & np.all(np.isfinite(lower), axis=1) & np.all(np.isfinite(upper), axis=1)
    return E, ConeSpec(nonneg=n_lin, soc=tuple(socs)), q, lower, upper, transform, built
