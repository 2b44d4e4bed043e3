"""Direct autocalibration (thesis chapter 7), the part both the solver and the verifier read
(numpy only): the program's frame and data, the chirality pairs of each orientation, what a
dual absolute quadric gives (plane at infinity, calibrations, upgrade), and the proof's check.

The program, for the reconstruction of ``problem.norm`` (image coordinates preconditioned by
K0^-1, so that K is near the identity; cameras in the reference frame, signs normalised):
cameras moved to the conditioning frame T (direct_relaxation.conditioning_frame: the linear
estimate of Q becomes diag(1, 1, 1, 0)) and scaled to Frobenius norm sqrt(3); Q in that frame has
trace 1; the objective is (7.12). Q in the input frame is T0 T Q T' T0', scaled to unit Frobenius
norm in the result.

Focal length (always): every view's DIAC w_i = P_i Q P_i' keeps (w_11 + w_22) / w_33 within what
the intrinsics ranges allow (focal_rows), two constraints linear in Q a view. Why: (7.12) measures
w's entries unnormalised, so a quadric whose views all see f -> 0 costs next to nothing. When the
cameras' principal axes meet in one point X0 (cameras looking at the scene's centre, the usual
capture), X0 projects to every principal point and Q = X0 X0' + e Q* (rank-3 rounded) costs ~0
for any scene: measured on a pixel-scale scene (12 views of 20 points, K = 800 px, 640 x 480, 0.5
px noise, cameras at distance 4 looking at the origin), the unconstrained global
minimum was such a quadric, cost 2.4e-7 and f = 7.3 px, against 4.8e-5 at the true K's polished
quadric (f = 800.5 px); with the focal rows the order-2 bound is 4.769087e-5, tight at the latter.

Chirality (options.chirality): "none"; "centers": every pair of signed camera centres on one side
of the plane at infinity; "points": also every point on the side of the centres (times an
orientation delta = +1 or -1 of the reconstruction, unknown: each orientation is either excluded
by an exact Gordan proof, as in the stratified method, or gets its own program; the bound is the
smaller of the programs').
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from geocert.formulations.autocalibration import direct_relaxation
from geocert.formulations.autocalibration import frames
from geocert.formulations.autocalibration import problem as autocalibration_problem
from geocert.formulations.autocalibration.proofs import check_recorded_bound
from geocert.formulations.autocalibration.problem import CHIRALITY, ORDERS  # the options it reads (problem.py checks them)
from geocert.core.geometry import InputError
from geocert.core.strict import Invalid, charge, dual_vector, informational, is_number, record, same, same_counts

RANK_TOLERANCE = 1e-4  # numerical rank: eigenvalues of the moment matrix above this times the largest
# Chirality pairs a program holds (one moment row each, about a hundred nonzeros): the signed
# centres with each other, and with "points" every point with every centre. Building 20,000
# takes about 2 s and 120 MB; an order-2 program of that many rows is also the most the solver
# is asked to solve (the kind refuses more, naming options/chirality, and so does the verifier
# before building anything).
MAX_CHIRALITY_PAIRS = 20_000


def chirality_pair_count(views: int, points: int, chirality: str) -> int:
    """How many chirality pairs a program of ``views`` cameras and ``points`` points holds."""
    if chirality == "none":
        return 0
    return views * (views - 1) // 2 + (views * points if chirality == "points" else 0)


def check_size(views: int, points: int, chirality: str) -> None:
    """InputError (options/chirality) when the program would hold more than MAX_CHIRALITY_PAIRS."""
    count = chirality_pair_count(views, points, chirality)
    if count > MAX_CHIRALITY_PAIRS:
        remedy = ('"none" or fewer cameras' if chirality == "centers" else '"centers" or give fewer points')
        raise InputError("options/chirality", f'"{chirality}" with {views} cameras and {points} points gives {count:,} '
                                              f"chirality pairs, more than {MAX_CHIRALITY_PAIRS:,}: choose {remedy}")


PSD_TOLERANCE = 1e-9  # a returned Q (rounded to JSON) counts as PSD of rank 3 within this of its norm


@dataclass
class Orientation:
    delta: float | None  # None: no chirality or centres only (no orientation to choose)
    pairs: np.ndarray | None  # (k, 4, 4) chirality pairs in the program's frame
    rows: np.ndarray | None  # the chirality rows (program frame), to check a solution
    centres: int = 0


@dataclass
class DirectSetup:
    problem: autocalibration_problem.Problem
    T: np.ndarray  # reference frame -> program frame (cameras P T)
    cameras: np.ndarray  # the program's data
    orientations: list[Orientation]
    excluded: list[dict]  # {"delta", "rows"}: orientations with no quasi-affine plane (Gordan)
    focal: np.ndarray | None = None  # (2 m, 4, 4) focal_rows of the program's cameras: tr(S Q) >= 0

    def to_input(self, Q: np.ndarray) -> np.ndarray:
        """Q of the program's frame in the input frame, unit Frobenius norm."""
        M = self.problem.norm.T0 @ self.T
        Q_in = M @ Q @ M.T
        Q_in = (Q_in + Q_in.T) / 2
        return Q_in / np.linalg.norm(Q_in)

    def from_input(self, Q_in: np.ndarray) -> np.ndarray:
        """Q of the input frame in the program's frame, trace 1."""
        M = np.linalg.inv(self.problem.norm.T0 @ self.T)
        Q = M @ Q_in @ M.T
        Q = (Q + Q.T) / 2
        return Q / np.trace(Q)


def _centres(cameras: np.ndarray) -> np.ndarray:
    c = np.array([frames.signed_centre(P) for P in cameras])
    return c / np.linalg.norm(c, axis=1)[:, None]


def focal_rows(cameras: np.ndarray, unit_ranges: dict) -> np.ndarray:
    """(2 m, 4, 4) symmetric S, unit Frobenius norm, with tr(S Q) >= 0 for every Q whose views'
    calibrations lie within the (preconditioned) intrinsics ranges. For K = [[f, s, u], [0, a f, v],
    [0, 0, 1]], w = K K' has w_11 + w_22 = (1 + a^2) f^2 + s^2 + u^2 + v^2 and w_33 = 1, so
        (1 + a_lo^2) f_lo^2 w_33 <= w_11 + w_22 <= ((1 + a_hi^2) f_hi^2 + max s^2 + max u^2 + max v^2) w_33,
    and with w = P Q P' (up to a positive scale: w_33 >= 0 for Q PSD) both are linear in Q:
    tr((p0 p0' + p1 p1' - c p2 p2') Q) >= 0 and tr((C p2 p2' - p0 p0' - p1 p1') Q) >= 0."""
    r = unit_ranges
    low = (1.0 + r["aspect"][0] ** 2) * r["focal"][0] ** 2
    high = ((1.0 + r["aspect"][1] ** 2) * r["focal"][1] ** 2 + max(abs(v) for v in r["skew"]) ** 2
            + max(abs(v) for v in r["u"]) ** 2 + max(abs(v) for v in r["v"]) ** 2)
    out = []
    for P in cameras:
        top = np.outer(P[0], P[0]) + np.outer(P[1], P[1])
        third = np.outer(P[2], P[2])
        out += [top - low * third, high * third - top]
    out = np.array(out)
    return out / np.linalg.norm(out, axis=(1, 2))[:, None, None]


def within_focal(setup: "DirectSetup", Q: np.ndarray, tolerance: float = 0.0) -> bool:
    """Whether Q (program frame, trace 1) meets every focal row, within ``tolerance``."""
    if setup.focal is None:
        return True
    return bool(np.all(np.einsum("kab,ab->k", setup.focal, Q) >= -tolerance))


def setup_for(problem: autocalibration_problem.Problem, chirality: str, exclude: bool = True) -> DirectSetup:
    """``exclude``: look for Gordan proofs excluding an orientation (the solver; the verifier
    keeps both orientations and reads the exclusions from the proof)."""
    norm = problem.norm
    if norm.reference_scale is not None:
        # the direct method is posed with the reference as given (its trace-one normalisation moves
        # with the frame's scale, and its answers and documents are that frame's)
        raise ValueError("the direct method takes a problem prepared with unit_reference=False")
    T = direct_relaxation.conditioning_frame(norm.cameras)
    cameras = direct_relaxation.framed_cameras(norm.cameras, T)
    to_frame = np.linalg.inv(T).T  # rows (points, centres) of the reference frame -> program frame

    def framed(rows):
        rows = rows @ to_frame
        return rows / np.linalg.norm(rows, axis=1)[:, None]

    centres = _centres(norm.cameras)
    excluded: list[dict] = []
    if chirality == "none":
        orientations = [Orientation(None, None, None)]
    elif chirality == "centers":
        rows = framed(centres)
        orientations = [Orientation(None, direct_relaxation.chirality_pairs(rows, len(rows)), rows, len(rows))]
    else:
        if norm.points is None:
            raise InputError("options/chirality", '"points" needs data/points (or choose "centers" or "none")')
        orientations = []
        for delta in (1.0, -1.0):
            ref_rows = frames.chirality_rows(norm, delta)
            chosen = frames.gordan_rows(ref_rows) if exclude else None
            if chosen is not None:
                excluded.append({"delta": delta, "rows": chosen})
                continue
            rows = framed(ref_rows)
            orientations.append(Orientation(delta, direct_relaxation.chirality_pairs(rows, len(centres)), rows,
                                            len(centres)))
    return DirectSetup(problem, T, cameras, orientations, excluded, focal_rows(cameras, problem.unit_ranges))




def chirality_holds(orientation: Orientation, Q: np.ndarray, tolerance: float = 0.0) -> bool:
    """Whether Q (program frame) satisfies the orientation's pairs: R_k' adj(Q) R_l >= 0."""
    if orientation.pairs is None:
        return True
    adj = adjugate(Q)
    values = np.einsum("kab,ab->k", orientation.pairs, adj)
    return bool(np.all(values >= -tolerance * np.abs(adj).max()))


def adjugate(Q: np.ndarray) -> np.ndarray:
    out = np.empty((4, 4))
    for a in range(4):
        for b in range(4):
            minor = np.delete(np.delete(Q, b, axis=0), a, axis=1)
            out[a, b] = (-1) ** (a + b) * np.linalg.det(minor)
    return out


def in_domain(setup: DirectSetup, Q: np.ndarray, excluded: tuple = ()) -> bool:
    """Q (program frame, trace 1) PSD of rank 3 within PSD_TOLERANCE, every view's focal length
    within the ranges (focal_rows, within PSD_TOLERANCE), and allowed by chirality in some
    orientation not excluded."""
    values = np.linalg.eigvalsh(Q)
    scale = np.abs(values).max()
    if not (values[0] >= -PSD_TOLERANCE * scale and abs(values[0]) <= PSD_TOLERANCE * scale and values[1] > 0):
        return False
    if not within_focal(setup, Q / np.trace(Q), PSD_TOLERANCE):
        return False
    return any(chirality_holds(o, Q, 1e-9) for o in setup.orientations if o.delta not in excluded)


def rank_three_projection(Q: np.ndarray) -> np.ndarray:
    """The nearest PSD matrix of rank 3 with trace 1 (eigenvalues clipped, the smallest zeroed)."""
    values, V = np.linalg.eigh((Q + Q.T) / 2)
    values = np.maximum(values, 0.0)
    values[0] = 0.0
    if values.sum() <= 0:
        values[1:] = 1.0
    out = (V * values) @ V.T
    return out / np.trace(out)


# --- what a dual absolute quadric gives ---------------------------------------------------------

def calibrations(cameras: np.ndarray, Q_in: np.ndarray) -> list[np.ndarray | None]:
    """K_i (pixels, K[2, 2] = 1) with K_i K_i' proportional to P_i Q P_i' (None if not definite)."""
    out = []
    for P in frames.unit_scaled(cameras):  # P Q P' squares a camera's scale
        omega = P @ Q_in @ P.T
        omega = (omega + omega.T) / 2
        if not omega[2, 2] != 0:
            out.append(None)
            continue
        omega = omega / omega[2, 2]
        try:
            K = autocalibration_problem.upper_triangular_root(omega)
        except np.linalg.LinAlgError:
            K = None
        out.append(K)
    return out


def mean_calibration(cameras: np.ndarray, Q_in: np.ndarray) -> np.ndarray | None:
    """One K for constant intrinsics: the root of the mean of the views' normalised P_i Q P_i'."""
    omegas = [P @ Q_in @ P.T for P in frames.unit_scaled(cameras)]
    omega = np.mean([(w + w.T) / 2 / w[2, 2] for w in omegas], axis=0)
    try:
        return autocalibration_problem.upper_triangular_root(omega)
    except np.linalg.LinAlgError:
        return None


def upgrade(cameras: np.ndarray, points: np.ndarray | None, Q_in: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(H, plane at infinity) with Q_in = H diag(1, 1, 1, 0) H' up to scale (thesis 7.2): H's
    first columns the eigenvectors of Q_in times the roots of their eigenvalues, its last the
    null vector, signed so that most points (without points: most cameras' viewing directions
    towards the centres' centroid) are in front of the metric cameras."""
    values, V = np.linalg.eigh(Q_in)
    order = np.argsort(-values)
    values, V = values[order], V[:, order]
    H = np.empty((4, 4))
    H[:, :3] = V[:, :3] * np.sqrt(np.maximum(values[:3], 0.0))
    H[:, 3] = V[:, 3]
    best, best_score = None, -math.inf
    for sign in (1.0, -1.0):
        Hs = H.copy()
        Hs[:, 3] *= sign
        try:
            cams = autocalibration_problem.metric_cameras(cameras, Hs)
        except (np.linalg.LinAlgError, ValueError):
            continue
        R = np.array([c["R"] for c in cams])
        C = np.array([c["center"] for c in cams])
        if points is not None:
            X = autocalibration_problem.metric_points(Hs, points)
            X = np.array([x for x in X if x is not None]).reshape(-1, 3)
            score = float(np.sum(np.einsum("ik,ijk->ij", R[:, 2], X[None, :, :] - C[:, None, :]) > 0))
        else:
            score = float(np.sum(np.einsum("ik,ik->i", R[:, 2], C.mean(axis=0) - C) > 0))
        if score > best_score:
            best, best_score = Hs, score
    if best is None:
        raise np.linalg.LinAlgError("no metric cameras from this quadric")
    plane = np.linalg.inv(best).T @ np.array([0.0, 0.0, 0.0, 1.0])
    return best, plane / np.linalg.norm(plane)


def derived(cameras: np.ndarray, points: np.ndarray | None, Q_in: np.ndarray, varying_focal: bool) -> dict:
    """The result's fields that follow from the returned quadric (the verifier recomputes them)."""
    H, plane = upgrade(cameras, points, Q_in)
    Ks = calibrations(cameras, Q_in)
    K = None if varying_focal else mean_calibration(cameras, Q_in)
    return {"plane_at_infinity": plane.tolist(), "K": None if K is None else K.tolist(),
            "Ks": [None if k is None else k.tolist() for k in Ks] if varying_focal else None,
            "upgrade": H.tolist(), "dual_absolute_quadric": Q_in.tolist(),
            "cameras": autocalibration_problem.metric_cameras(cameras, H),
            "points": autocalibration_problem.metric_points(H, points)}


# --- the proof --------------------------------------------------------------------------------

def check_rank(rank, ratio, order: int, where: str) -> None:
    """A moment matrix's rank and eigenvalue ratio as the rank test states them (informational,
    but never what no moment matrix of this order has): a rank from 1 to the matrix's size (its
    largest eigenvalue is positive: its corner y_0 is 1), a ratio of the second eigenvalue to the
    first at most 1, and the two agreeing: rank 1 exactly when the ratio is within RANK_TOLERANCE."""
    informational(rank, f"{where}/moment_rank", "integer")
    informational(ratio, f"{where}/eigenvalue_ratio")
    size = len(direct_relaxation.monomials(order))
    if rank is not None and not (type(rank) is int and 1 <= rank <= size):
        raise Invalid("format", f"{where}/moment_rank is {rank!r:.40}: a rank from 1 to {size} (the order-{order} "
                                "moment matrix's size), or null")
    if ratio is not None and not ratio <= 1:
        raise Invalid("format", f"{where}/eigenvalue_ratio is {ratio!r:.40}: the second eigenvalue over the first "
                                "is at most 1")
    if rank is not None and ratio is not None and (rank == 1) != (ratio <= RANK_TOLERANCE):
        raise Invalid("format", f"{where}: moment_rank {rank} and eigenvalue_ratio {ratio!r:.12} disagree (rank 1 "
                                f"exactly when the ratio is at most {RANK_TOLERANCE:g})")


def check_proof(setup: DirectSetup, proof: dict, order: int) -> tuple[float, tuple]:
    """The bound a "direct_moment" proof establishes over the program's feasible set, and the
    orientations it excludes: each orientation of the setup (built with exclude=False) is either
    excluded exactly (Gordan, rational arithmetic) or bounded by the safe bound of its dual."""
    record(proof, "proof", ("type", "order", "programs", "excluded"),
           ("reference", "moment_rank", "eigenvalue_ratio", "sublevel"))  # reference: the verifier's check_claim
    informational(proof.get("moment_rank"), "proof/moment_rank", "integer")  # they explain a bound, prove nothing
    informational(proof.get("eigenvalue_ratio"), "proof/eigenvalue_ratio")
    if not same_counts(proof.get("order"), order):  # a count: 2.0 is not 2 (review 62)
        raise Invalid("program", f"the proof is for relaxation order {proof.get('order')!r}, not {order}")
    check_rank(proof.get("moment_rank"), proof.get("eigenvalue_ratio"), order, "proof")
    excluded, programs = proof.get("excluded"), proof.get("programs")
    if not isinstance(excluded, list) or not isinstance(programs, list):
        raise Invalid("format", "a direct proof has excluded and programs lists")
    gone = []
    for number, program in enumerate(programs):
        record(program, f"programs/{number}", ("delta", "z", "bound"), ("cuts",))
        informational(program.get("bound"), f"programs/{number}/bound")  # recomputed from z
    for item in excluded:
        if isinstance(item, dict):
            record(item, "excluded", ("delta", "rows"))
        # a number, never a boolean (true == 1.0 in Python)
        if not isinstance(item, dict) or not is_number(item.get("delta")) or item.get("delta") not in (1.0, -1.0) \
                or setup.orientations[0].delta is None:
            raise Invalid("format", "excluded items are {delta: 1.0 or -1.0, rows} (chirality points only)")
        # One exclusion an orientation, as the stratified proofs' (proofs.check_regions): each is
        # an exact test over rows rebuilt from the data, which no charge pays for, so a list
        # repeating one (a genuine exclusion 20,000 times, 1 MB) took 9.5 s to verify.
        if float(item["delta"]) in gone:
            raise Invalid("format", f"excluded: orientation {item['delta']:+g} is excluded twice (one exclusion an "
                                    "orientation)")
        rows = frames.chirality_rows(setup.problem.norm, float(item["delta"]))
        chosen = item.get("rows")
        if not (isinstance(chosen, list) and all(isinstance(k, int) and not isinstance(k, bool) for k in chosen)
                and frames.exact_gordan(rows, chosen)):
            raise Invalid("root_region", f"orientation {item['delta']:+g}: the rows do not exclude it")
        gone.append(float(item["delta"]))
    # Every program is one of an orientation left to bound, and is read there: a program of an
    # excluded orientation, or of none (a delta no orientation has), would be a record no check
    # reads, its z, delta and cuts of any type.
    live = [o.delta for o in setup.orientations if o.delta not in gone]
    for number, program in enumerate(programs):
        if not any(_of_orientation(program.get("delta"), delta) for delta in live):
            raise Invalid("format", f"programs/{number}: delta {program.get('delta')!r:.40} is not an orientation "
                                    f"left to bound ({', '.join(map(repr, live)) or 'none'}): a program no check "
                                    "reads proves nothing")
    bound = math.inf
    for o in setup.orientations:
        if o.delta in gone:
            continue
        match = [p for p in programs if isinstance(p, dict) and _of_orientation(p.get("delta"), o.delta)]
        leaves = [_cuts(p.get("cuts", [])) for p in match]
        if not match or not covers(leaves):
            raise Invalid("root_region", f"orientation {o.delta!r} needs one program, or the leaves of a split "
                                         "covering its feasible set, or an exclusion")
        for item, cuts in zip(match, leaves):
            # The dual vector's length before the program is built (its rows: those without the
            # pairs, one a pair): a short vector costs nothing, a long one pays for its program.
            rows = _rows_without_pairs(setup, order, len(cuts)) + (0 if o.pairs is None else len(o.pairs))
            charge(rows, f"the program of orientation {o.delta!r}")
            dual_vector(item.get("z"), rows, f"programs/{o.delta}/z", "leaf_bounds")
            program = direct_relaxation.build(setup.cameras, o.pairs, order, cuts, setup.focal)
            z = dual_vector(item.get("z"), len(program.b), f"programs/{o.delta}/z", "leaf_bounds")
            value, _ = direct_relaxation.safe_bound(program, z)
            check_recorded_bound(item.get("bound"), value, f"programs/{o.delta}", PROGRAM_RECORD_TOLERANCE)
            bound = min(bound, value)
    if bound == math.inf:
        raise Invalid("root_region", "every orientation is excluded: nothing to bound")
    return bound, tuple(gone)


# A direct program's recorded bound is its solver's safe bound from the dual vector before it was
# written (certificates.pack); the vector as read gives a bound 4.5e-6 of itself lower on the stored
# direct document (its entries 1e6 times the bound). Held to a thousandth: a record is the solver's,
# not a claim (a 1e308 record verified, review 41).
PROGRAM_RECORD_TOLERANCE = 1e-3


def _of_orientation(stated: Any, delta: float | None) -> bool:
    """Whether a program's stated delta names the orientation ``delta`` (None: the one of
    "centers" and "none"; a number, never a boolean, otherwise)."""
    if delta is None:
        return stated is None
    return isinstance(stated, (int, float)) and not isinstance(stated, bool) and stated == delta


def _rows_without_pairs(setup: DirectSetup, order: int, cuts: int) -> int:
    """The rows of a program of ``cuts`` cuts without its chirality pairs (its size does not
    depend on the cuts' values or the cameras' numbers)."""
    return len(direct_relaxation.build(setup.cameras, None, order, ((0, 0.0, 1.0),) * cuts, setup.focal).b)


# Cuts on one program's path from its orientation's root: the solver splits at most this often
# (direct_solve.MAX_SPLITS is this), and a bound keeps a hostile document from asking the verifier
# for programs with any number of localizing blocks, or a splitting of any depth.
MAX_CUTS = 3


def _cuts(raw) -> tuple:
    """A program's cuts as ((k, c, sign), ...), checked: k an entry of x, c finite, sign +-1."""
    if not isinstance(raw, list) or len(raw) > MAX_CUTS:
        raise Invalid("format", f"a program's cuts are a list of at most {MAX_CUTS} [k, c, sign]")
    out = []
    for cut in raw:
        if not (isinstance(cut, list) and len(cut) == 3):
            raise Invalid("format", "a cut is [k, c, sign]")
        k, c, sign = cut
        if not (isinstance(k, int) and not isinstance(k, bool) and 0 <= k < direct_relaxation.N
                and isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c)
                and sign in (1, -1) and not isinstance(sign, bool)):
            raise Invalid("format", "a cut is [k (0 to 8), c (finite), sign (1 or -1)]")
        out.append((k, float(c), float(sign)))
    return tuple(out)


def covers(leaves: list[tuple]) -> bool:
    """Whether leaves (each a path of cuts from the root) are the leaves of one binary splitting
    of the whole set: a single empty path, or every path starting with a cut on one (k, c), the
    sign +1 paths and the sign -1 paths (that cut removed) each covering in turn. (x_k <= c and
    x_k >= c cover the line; each path's cuts are its leaf's program's constraints.)"""
    if len(leaves) == 1 and not leaves[0]:
        return True
    if not leaves or any(not path for path in leaves):
        return False
    k, c = leaves[0][0][0], leaves[0][0][1]
    if any(path[0][:2] != (k, c) for path in leaves):
        return False
    halves = [[path[1:] for path in leaves if path[0][2] == sign] for sign in (1.0, -1.0)]
    return all(covers(half) for half in halves)


