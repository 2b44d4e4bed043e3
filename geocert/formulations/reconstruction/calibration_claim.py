"""What a reconstruction's summary.calibration states about K, as figures the pipeline writes
and the verifier recomputes from the returned cameras (numpy only): whether two K are the same,
how far the returned K moved from the certified one, and which certified intrinsics lie on the
edge of the autocalibration's search range (there the range, not the tracks, stops the optimum,
so K is not determined by the data)."""

from __future__ import annotations

import numpy as np

EDGE_FRACTION = 0.01  # a certified intrinsic within this fraction of its range's width from an end is on the edge
SAME = 1e-9  # relative to K's largest entry: the same K up to rounding and JSON round trips
# Cameras built as K [R | t] for one K give it back to this (relative to its largest entry) after
# rounding; cameras of a projective reconstruction do not share a K by chance.
BUILT_WITH_ONE_K = 1e-6


# The returned_K_not_certified warning (every form the pipeline has written): what moved K, how far
# (difference's focal percent and principal point pixels), and which K the cameras use.
MOVED_BY = {True: "the bundle adjustment", False: "the camera model (no adjustment)"}
MOVED_WHICH = {"shared": "the cameras returned use the adjusted K",
               "varying": "each camera has its own focal length (camera_model \"varying\"), calibration.K the middle "
                          "one's",
               "per_view": "each camera has its own principal point (principal_point \"per_view\"), calibration.K "
                           "the middle one's"}


def moved_figures(moved: dict) -> str:
    """How far K moved (``difference``'s dict), as the warning states it."""
    return f"focal {moved['focal_percent']:+.2f}%, principal point {moved['principal_point_px']:.1f} px"


def moved_warning(adjusted: bool, which: str, moved: dict) -> str:
    """The returned_K_not_certified warning's words (``which`` a key of MOVED_WHICH)."""
    return (f"{MOVED_BY[adjusted]} moved K from the certified one ({moved_figures(moved)}): {MOVED_WHICH[which]}; "
            "the certificate is about calibration.certified_K")


def edge_warning(edges) -> str:
    """The certified_K_on_range_edge warning's words (``edges``: on_range_edge's names)."""
    return (f"the certified K's {', '.join(edges)} lies on the edge of its search range: the range, not the tracks, "
            "stops it there; widen options.intrinsics to let the data decide")


def K_given(stage: dict) -> bool:
    """Whether the autocalibration stage (its document) was skipped because K was given: the
    critical_motion warning's ending then says so (read alike by the pipeline and the verifier)."""
    return stage.get("status") == "skipped" and "K is known" in str(stage.get("reason") or "")


def critical_warning(critical: str, known: bool) -> str:
    """The critical_motion warning's words (``known``: K was given)."""
    return (f"{critical}: the tracks do not determine a constant K"
            + ("; K was given, so the reconstruction does not rely on them for it" if known else ""))


CALIBRATED_CAMERAS_WARNING = (
    "the projective cameras the certified K upgrades are the registration's, built as K [R | t] with one K: the "
    "certificate proves that this K upgrades them optimally, which they already assume, not that the tracks alone "
    "fix K (calibration.determined says whether the motion does)")


def same(a, b) -> bool:
    """``a`` is ``b`` within SAME of b's scale, both finite (an infinite entry would make the scale
    infinite and any ``a`` the same)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return bool(a.shape == b.shape and np.all(np.isfinite(a)) and np.all(np.isfinite(b))
                and np.all(np.abs(a - b) <= SAME * max(1.0, float(np.abs(b).max()))))


def middle_centre(centres) -> int:
    """The index of the principal point (of ``centres``, (n, 2)) nearest the median of them (ties:
    the first)."""
    centres = np.asarray(centres, dtype=float)
    return int(np.argmin(np.linalg.norm(centres - np.median(centres, axis=0), axis=1)))


def stated_camera(Ks) -> int:
    """Which camera's K (``Ks``: the K of each camera returned, in view order) a result whose
    cameras have a K each states as summary.calibration.K (the claim's model "varying"): where
    they share their principal point, skew and aspect (camera_model "varying": a focal length
    each), the middle focal length's (sorted, index len // 2); else (a principal point per view)
    among the cameras sharing the focal length most of them share (ties: the earliest camera's;
    all of them where one focal length is every camera's), the one whose principal point lies
    nearest the median of theirs (middle_centre). The pipeline picks it among the cameras it
    returns, after the sanity layer has dropped any (pipeline._check_cameras), and the verifier
    recomputes it from them."""
    Ks = [np.asarray(K, dtype=float) for K in Ks]
    focals = np.array([K[0, 0] for K in Ks])
    rest = [np.array([K[0, 1], K[0, 2], K[1, 2], K[1, 1] / K[0, 0]]) for K in Ks]
    if all(same(r, rest[0]) for r in rest):
        return int(np.argsort(focals, kind="stable")[len(focals) // 2])
    values = list(dict.fromkeys(focals.tolist()))  # each focal length once, in order of its first camera
    most = values[int(np.argmax([np.count_nonzero(focals == f) for f in values]))]  # argmax: the first of a tie
    group = np.flatnonzero(focals == most)
    return int(group[middle_centre(np.array([K[:2, 2] for K in Ks])[group])])


def intrinsics(K) -> dict:
    K = np.asarray(K, dtype=float)
    return {"focal": float(K[0, 0]), "aspect": float(K[1, 1] / K[0, 0]), "skew": float(K[0, 1]),
            "principal_point": [float(K[0, 2]), float(K[1, 2])]}


def difference(K, certified_K) -> dict:
    """How far K is from certified_K: focal length (percent), principal point (pixels), aspect
    and skew (pixels)."""
    a, b = intrinsics(K), intrinsics(certified_K)
    return {"focal_percent": 100.0 * (a["focal"] / b["focal"] - 1.0),
            "principal_point_px": float(np.hypot(a["principal_point"][0] - b["principal_point"][0],
                                                 a["principal_point"][1] - b["principal_point"][1])),
            "aspect": a["aspect"] - b["aspect"], "skew_px": a["skew"] - b["skew"]}


def on_range_edge(K, ranges: dict) -> list[str]:
    """The intrinsics of K within EDGE_FRACTION of an end of their range (ranges as the
    autocalibration states them: focal, aspect, skew [lo, hi], principal_point [[u], [v]])."""
    values, edges = intrinsics(K), []
    pairs = [(name, values[name], ranges.get(name)) for name in ("focal", "aspect", "skew")]
    pp = ranges.get("principal_point")
    if pp is not None:
        pairs += [("principal_point_u", values["principal_point"][0], pp[0]),
                  ("principal_point_v", values["principal_point"][1], pp[1])]
    for name, value, bounds in pairs:
        if bounds is None:
            continue
        if not bounds[1] > bounds[0]:  # pinned: the range fixes it (aspect and skew are often fixed by assumption)
            if name not in ("aspect", "skew"):
                edges.append(name)
            continue
        where = (value - bounds[0]) / (bounds[1] - bounds[0])
        if where <= EDGE_FRACTION or where >= 1 - EDGE_FRACTION:
            edges.append(name)
    return edges


def built_with_one_K(cameras) -> bool:
    """Whether projective cameras (n, 3, 4) are all K [R | t] for one K: then a certificate that
    K upgrades them optimally proves what they were built with, not what their tracks fix."""
    Ks = []
    for P in np.asarray(cameras, dtype=float):
        K = camera_intrinsics(P)
        if K is None:
            return False
        Ks.append(K)
    return len(Ks) >= 2 and all(np.all(np.abs(K - Ks[0]) <= BUILT_WITH_ONE_K * float(np.abs(Ks[0]).max()))
                                for K in Ks[1:])


def camera_intrinsics(P: np.ndarray) -> np.ndarray | None:
    """The upper-triangular K (positive diagonal, K[2, 2] = 1) of a 3x4 camera P = K [R | t], from
    the Cholesky factor of P's left 3x3 times its transpose (None when that is not positive definite)."""
    J = np.eye(3)[::-1]
    omega = P[:, :3] @ P[:, :3].T
    try:
        L = np.linalg.cholesky(J @ (omega / omega[2, 2]) @ J)
    except np.linalg.LinAlgError:
        return None
    K = J @ L @ J
    return K * np.sign(np.diag(K))[None, :] / abs(K[2, 2])
