"""The reconstruction kind's verification adapter (numpy only).

Its claims are the points, each a triangulation in the cameras the certificate's data state, so
they are checked as the triangulation kind's are (TrackItems). ``check_result`` ties the rest of
a result to them (docs/certificate.md, "Reconstruction"):

- the cameras: one per view in view order; the registered ones (the views the certificate's data
  list) return the P the points are certified in, and K, R, t and the centre that P gives
  (P = K [R | t], K upper triangular with K[2][2] = 1 and a positive diagonal, R a rotation,
  centre -R' t); the others return none of them and claim nothing;
- each point's observations are the track the certificate's data hold for it;
- every camera the result calls certified, or gives a lower bound, is backed by the camera
  certificate beside it: a valid resection document solved with the result's norm, max_residual,
  abs_gap and camera_rel_gap, one map per searched camera built from the returned points, in
  view order; a certified camera's cost is recomputed from its P, every point lies in front of
  it (the resection bound's scope), its lower bound is at most the proven one and its cost, its
  gap is cost - lower_bound, and its cost at most (1 + tolerance) times the proven bound plus
  abs_gap, the tolerance recomputed (camera_claim) from its points, the norm, camera_rel_gap and
  its degrees of freedom, which the returned cameras' K give;
- the summary's counts and RMS are recomputed from the items;
- summary.calibration is about the K returned: its K the cameras', its certified_K the one the
  autocalibration stage states, the difference, the range edges and ``determined`` recomputed,
  the summary's autocalibration_certified and autocalibration_determined its own, and each of
  its warnings (and views not registered) said.

A camera no bound could certify is not searched (structure.resect_cameras) and claims no bound.
(A result without ``searched`` on its cameras, from before it was stated, is read as every
registered camera searched.) The metric upgrade's own certification (the autocalibration stage's
``certified``, the summary's ``autocalibration_certified``) is the pipeline's statement: this
document carries no proof of it, and the report's scope says so.
"""

from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from geocert.solvers.core.geometry import is_number, norm_cost
from geocert.solvers.core.strict import Invalid, number, numbers
from geocert.solvers.fractional.items import TrackItems
from geocert.solvers.reconstruction import calibration_claim, camera_claim

ROUNDING = 1e-9  # relative: what JSON round trips and a recomputed cost may differ by
CAMERA_FIELDS = ("K", "R", "t", "center", "P")


def _views_of(cameras: list[dict]) -> list[dict]:
    """The registered cameras, in view order: the cameras the certificates' data list."""
    return [camera for camera in cameras if camera.get("P") is not None and camera.get("K") is not None]


def camera_maps(points: list[dict], views: list[int]) -> list[dict]:
    """Each view's resection data from the returned points: every observation of a finite point
    in that view, as (source point, target pixel)."""
    maps = {view: {"source": [], "target": []} for view in views}
    for point in points:
        if point.get("point") is None or point.get("at_infinity"):
            continue
        for view, u, v in point.get("observations") or []:
            if int(view) in maps:
                maps[int(view)]["source"].append(list(point["point"]))
                maps[int(view)]["target"].append([u, v])
    return [maps[view] for view in views]


def _close(value: Any, expected: float, scale: float = 1.0) -> bool:
    return is_number(value) and abs(value - expected) <= ROUNDING * max(scale, abs(expected))


def _check_camera_fields(camera: dict, where: str) -> None:
    """K, R, t and the centre are what the camera's P gives (they fix each other: P's third row is
    R's, of unit norm, so K [R | t] = P with K[2][2] = 1 leaves no scale free)."""
    P = numbers(camera.get("P"), f"{where}/P", (3, 4), "returned")
    K = numbers(camera.get("K"), f"{where}/K", (3, 3), "returned")
    R = numbers(camera.get("R"), f"{where}/R", (3, 3), "returned")
    t = numbers(camera.get("t"), f"{where}/t", (3,), "returned")
    centre = numbers(camera.get("center"), f"{where}/center", (3,), "returned")
    if not (K[1, 0] == K[2, 0] == K[2, 1] == 0 and K[2, 2] == 1 and K[0, 0] > 0 and K[1, 1] > 0):
        raise Invalid("returned", f"{where}/K must be upper triangular with K[2][2] = 1 and a positive diagonal")
    if not (np.abs(R @ R.T - np.eye(3)).max() <= ROUNDING and np.linalg.det(R) > 0):
        raise Invalid("returned", f"{where}/R is not a rotation")
    scale = np.abs(P).max()
    if not np.abs(K @ np.column_stack([R, t]) - P).max() <= ROUNDING * scale:
        raise Invalid("returned", f"{where}: K [R | t] is not its P")
    if not np.abs(centre + R.T @ t).max() <= ROUNDING * max(1.0, np.abs(t).max()):
        raise Invalid("returned", f"{where}/center is not -R' t")


def _check_cameras(cameras: Any, stated: list) -> tuple[list[dict], list[int]]:
    """The cameras in view order, the registered ones those the certificate's data state."""
    if not isinstance(cameras, list) or not all(isinstance(c, dict) for c in cameras):
        raise Invalid("returned", "the result's cameras must be a list of objects")
    if [camera.get("view") for camera in cameras] != list(range(len(cameras))):
        raise Invalid("returned", "the result's cameras must be one per view, in view order")
    registered = _views_of(cameras)
    views = [camera["view"] for camera in registered]
    if stated.get("cameras") != [camera["P"] for camera in registered] or stated.get("views", views) != views:
        raise Invalid("returned", "the cameras the points are certified in are not the cameras returned")
    chosen = {id(camera) for camera in registered}
    for camera in cameras:
        where = f"cameras/{camera['view']}"
        if id(camera) in chosen:
            _check_camera_fields(camera, where)
            if camera.get("registered") is not True:
                raise Invalid("returned", f"{where}: a camera with a P is registered")
            continue
        if any(camera.get(name) is not None for name in CAMERA_FIELDS + ("cost", "lower_bound", "gap")) or \
                camera.get("certified") is not False or camera.get("registered") is not False or \
                camera.get("searched", False) is not False:
            raise Invalid("returned", f"{where}: a camera not registered returns no camera and claims nothing")
    return registered, views


def _check_points(points: Any, tracks: Any, views: list[int]) -> None:
    """Each point's observations are its track in the certificate's data (views by position)."""
    if not isinstance(points, list) or not isinstance(tracks, list) or len(points) != len(tracks):
        raise Invalid("returned", "the result's points are not the certificate's tracks")
    for index, (point, track) in enumerate(zip(points, tracks)):
        observations = point.get("observations") if isinstance(point, dict) else None
        if not isinstance(observations, list) or not all(isinstance(o, list) and len(o) == 3 for o in observations):
            raise Invalid("returned", f"points/{index}/observations must be [view, u, v] triples")
        stated = [[views[k], u, v] for k, (u, v) in zip(track["views"], track["points"])]
        if observations != stated:
            raise Invalid("returned", f"points/{index}/observations are not the track its certificate is about")


def _check_summary(result: dict, registered: list[dict]) -> None:
    """The summary's counts and RMS, recomputed from the items (pipeline._summarise's)."""
    summary = result.get("summary")
    if not isinstance(summary, dict):
        raise Invalid("returned", "the result's summary must be an object")
    cameras, points = result["cameras"], result["points"]
    placed = [p for p in points if p.get("point") is not None]
    count, squared = 0, 0.0
    by_view = {camera["view"]: np.asarray(camera["P"], dtype=float) for camera in registered}
    for point in placed:
        X = np.asarray(point["point"] if point.get("at_infinity") else [*point["point"], 1.0], dtype=float)
        for view, u, v in point["observations"]:
            proj = by_view[int(view)] @ X
            squared += (proj[0] / proj[2] - u) ** 2 + (proj[1] / proj[2] - v) ** 2
            count += 1
    bounded = [c for c in cameras if c.get("status") not in ("not_run", "cancelled")]
    certified_points = sum(1 for p in points if p.get("certified") is True)
    certified_cameras = sum(1 for c in cameras if c.get("certified") is True)
    expected = {"views": len(cameras), "views_registered": len(registered), "points": len(points),
                "observations": count, "points_certified": certified_points,
                "points_certified_fraction": certified_points / len(points) if points else None,
                "cameras_certified": certified_cameras,
                "cameras_certified_fraction": certified_cameras / len(bounded) if bounded else None}
    for name, value in expected.items():
        given = summary.get(name)
        if not (given == value or (value is not None and _close(given, value))):
            raise Invalid("returned", f"summary/{name} is {given!r}, the items give {value!r}")
    rms = math.sqrt(squared / count) if count else None
    given = summary.get("rms_reprojection_px")
    if not (given is rms or (rms is not None and _close(given, rms, 1e-6))):
        raise Invalid("returned", f"summary/rms_reprojection_px is {given!r}, the cameras and points give {rms!r}")
    for stage in result.get("stages") or []:  # the stages' counts of the same items
        if not isinstance(stage, dict):
            continue
        counts = {"structure": {"points": len(points), "certified": certified_points},
                  "cameras": {"cameras": len(registered), "certified": certified_cameras,
                              "searched": sum(1 for c in cameras if c.get("searched") is True)}}.get(stage.get("name"))
        for name, value in (counts or {}).items():
            if name in stage and stage[name] != value:
                raise Invalid("returned", f"stages/{stage['name']}/{name} is {stage[name]!r}, the items give {value!r}")


def _warned(summary: dict, code: str) -> bool:
    warnings = summary.get("warnings")
    return isinstance(warnings, list) and any(isinstance(w, dict) and w.get("code") == code for w in warnings)


def _check_calibration(result: dict, registered: list[dict]) -> None:
    """summary.calibration is about the K the cameras return (claims.CalibrationClaim): its K is
    every registered camera's (model "shared") or one focal length among theirs with their
    principal point and skew ("varying"); certified_K is stated exactly when certified, and is
    the returned K exactly when returned_is_certified (then source "autocalibration"); the
    difference and the certified intrinsics on their range's edge (the autocalibration stage's
    ranges) are recomputed; determined only when certified, off the edge and with no critical
    motion; the summary's autocalibration_certified and autocalibration_determined are its own;
    a returned K not the certified one, a certified K on the edge, a critical motion and views
    not registered each have their warning. That the certified K is the autocalibration's
    optimum is the pipeline's statement (the scope says so): no proof of it is carried here. A
    result without summary.calibration (from before it was stated) makes none of these claims."""
    summary = result["summary"]
    missing = sum(1 for camera in result["cameras"] if camera.get("registered") is not True)
    if missing and "calibration" in summary and not _warned(summary, "views_not_registered"):
        raise Invalid("returned", f"summary: {missing} views not registered, and no views_not_registered warning "
                                  "says so")
    claim = summary.get("calibration")
    if claim is None:
        return
    if not isinstance(claim, dict):
        raise Invalid("returned", "summary/calibration must be an object")
    where = "summary/calibration"
    Ks = [numbers(camera["K"], f"cameras/{camera['view']}/K", (3, 3), "returned") for camera in registered]
    K = None if claim.get("K") is None else numbers(claim["K"], f"{where}/K", (3, 3), "returned")
    certified, model = claim.get("certified"), claim.get("model", "shared")
    if (K is None) != (not Ks):
        raise Invalid("returned", f"{where}/K must be stated exactly when cameras with a K are returned")
    if K is not None and model == "shared" and not all(calibration_claim.same(k, K) for k in Ks):
        raise Invalid("returned", f"{where}/K is not every registered camera's K (model shared)")
    if K is not None and model == "varying":
        rest = np.array([[k[0, 1], k[0, 2], k[1, 2], k[1, 1] / k[0, 0]] for k in Ks + [K]])
        focals = [k[0, 0] for k in Ks]
        if not (all(calibration_claim.same(r, rest[-1]) for r in rest) and min(focals) <= K[0, 0] <= max(focals)):
            raise Invalid("returned", f"{where}/K is not one of the registered cameras' focal lengths with their "
                                      "shared intrinsics (model varying)")
    if model not in ("shared", "varying") or certified not in (True, False):
        raise Invalid("returned", f"{where}: model must be shared or varying, certified a boolean")
    cert = claim.get("certified_K")
    if (cert is not None) != (certified is True) or (certified and K is None):
        raise Invalid("returned", f"{where}/certified_K is stated exactly when a certified K is claimed beside a "
                                  "returned one")
    cert = None if cert is None else numbers(cert, f"{where}/certified_K", (3, 3), "returned")
    stage = next((s for s in result.get("stages") or [] if isinstance(s, dict) and s.get("name") == "autocalibration"),
                 {})
    if cert is not None and not (stage.get("certified") is True and stage.get("K") is not None
                                 and calibration_claim.same(numbers(stage["K"], "stages/autocalibration/K", (3, 3),
                                                                    "returned"), cert)):
        raise Invalid("returned", f"{where}/certified_K is not the K the autocalibration stage certified")
    returned = bool(cert is not None and model == "shared" and calibration_claim.same(K, cert))
    if claim.get("returned_is_certified") is not returned:
        raise Invalid("returned", f"{where}/returned_is_certified is {claim.get('returned_is_certified')!r}: the "
                                  f"returned K is {'' if returned else 'not '}the certified one")
    source = claim.get("source")
    if (source == "autocalibration") != returned or (source == "none") != (K is None):
        raise Invalid("returned", f"{where}/source {source!r} is not where the returned K comes from")
    expected = None if cert is None else calibration_claim.difference(K, cert)
    given = claim.get("difference")
    if (expected is None) != (given is None) or (expected is not None and not (
            isinstance(given, dict) and all(_close(given.get(name), value, 1.0) for name, value in expected.items()))):
        raise Invalid("returned", f"{where}/difference is {given!r}, the returned and certified K give {expected!r}")
    ranges = stage.get("intrinsics") if isinstance(stage.get("intrinsics"), dict) else {}
    edges = [] if cert is None else calibration_claim.on_range_edge(cert, ranges)
    if claim.get("on_range_edge") != edges:
        raise Invalid("returned", f"{where}/on_range_edge is {claim.get('on_range_edge')!r}, the certified K and "
                                  f"the autocalibration's ranges give {edges!r}")
    critical = summary.get("critical_motion") or stage.get("critical_motion")
    determined = claim.get("determined")
    if determined is True and (not certified or edges or critical):
        raise Invalid("returned", f"{where}/determined is true, but K is "
                                  + ("not certified" if not certified else "on its range's edge" if edges
                                     else f"under a critical motion ({critical})"))
    if summary.get("autocalibration_certified") is not certified or summary.get("autocalibration_determined") \
            is not determined:
        raise Invalid("returned", "summary: autocalibration_certified and autocalibration_determined must be "
                                  "summary/calibration's certified and determined")
    for code, due in (("returned_K_not_certified", certified and not returned), ("certified_K_on_range_edge", edges),
                      ("critical_motion", critical)):
        if due and not _warned(summary, code):
            raise Invalid("returned", f"summary: no {code} warning, though the calibration calls for it")


def _check_camera_certificate(result: dict, certificate: dict, searched: list[dict], certified: list[int],
                              verify: Callable[[dict], object]) -> None:
    """The camera certificate backs the certified cameras, and is about this result: the
    resection kind, the result's norm, max_residual, abs_gap and camera tolerance, and one map
    per searched camera built from the returned points."""
    document = result.get("camera_certificate")
    if not certified and document is None:
        return
    if not isinstance(document, dict):
        raise Invalid("returned", "cameras are called certified without a camera certificate")
    options, own = document.get("options"), certificate["options"]
    if document.get("kind") != "resection" or not isinstance(options, dict):
        raise Invalid("returned", "the camera certificate must be a resection certificate")
    tolerance = own.get("camera_rel_gap", own.get("rel_gap"))  # the raw options: as the pipeline passed them
    expected = {"norm": result.get("norm"), "max_residual": own.get("max_residual"), "abs_gap": own.get("abs_gap"),
                "rel_gap": tolerance}
    for name, value in expected.items():
        given = options.get(name)
        if not (given == value and type(given) is type(value)) and not (is_number(given) and is_number(value)
                                                                        and float(given) == float(value)):
            raise Invalid("returned", f"the camera certificate's {name} is {given!r}, the result's is {value!r}")
    report = verify(document)
    if not getattr(report, "valid", False):
        raise Invalid("returned", f"the camera certificate is invalid: {getattr(report, 'first_failure', None)}")
    discounted = {entry["item"]: entry["proven"] for entry in (report.scope or {}).get("discounted", [])}
    claims, maps = document.get("items"), document.get("data", {}).get("maps")
    if not isinstance(claims, list) or not isinstance(maps, list) or len(claims) != len(searched) \
            or len(maps) != len(searched):
        raise Invalid("returned", f"the camera certificate must hold one map per searched camera ({len(searched)}, "
                                  "in view order)")
    expected_maps = camera_maps(result.get("points") or [], [int(camera["view"]) for camera in searched])
    for k, camera in enumerate(searched):
        if maps[k] != expected_maps[k]:
            raise Invalid("returned", f"cameras/{camera.get('view')}: the camera certificate's map is not the "
                                      "returned points")
    norm = result.get("norm")
    dof = camera_claim.degrees_of_freedom([camera["K"] for camera in _views_of(result["cameras"])])
    for k, camera in enumerate(searched):
        claim, where = claims[k], f"cameras/{camera.get('view')}"
        proven = discounted.get(k, claim.get("lower_bound"))
        source = np.asarray(maps[k]["source"], dtype=float).reshape(-1, 3)
        target = np.asarray(maps[k]["target"], dtype=float).reshape(-1, 2)
        lower = camera.get("lower_bound")
        if lower is not None and claim.get("certified") is True and not (is_number(lower) and lower <= proven):
            raise Invalid("returned", f"{where}: lower bound {lower!r} above the proven {proven!r}")
        if camera.get("points") is not None and camera["points"] != len(source):
            raise Invalid("returned", f"{where}: points {camera['points']!r}, its map has {len(source)}")
        if k not in certified:
            continue
        if claim.get("certified") is not True:
            raise Invalid("returned", f"{where}: called certified, but its resection is not")
        P = np.asarray(camera["P"], dtype=float)
        projected = np.hstack([source, np.ones((len(source), 1))]) @ P.T
        if not np.all(projected[:, 2] > 0):
            raise Invalid("returned", f"{where}: a point is behind the camera returned, outside the bound's scope")
        cost = norm_cost(target - projected[:, :2] / projected[:, 2:3], norm)
        claimed_cost = camera.get("cost")
        if not math.isfinite(cost) or not _close(claimed_cost, cost):
            raise Invalid("returned", f"{where}: cost {claimed_cost!r}, but the returned camera costs {cost!r}")
        if not (is_number(lower) and lower <= cost * (1 + ROUNDING)):
            raise Invalid("returned", f"{where}: lower bound {lower!r} is not a number at most its cost {cost!r}")
        if not (_close(camera.get("gap"), claimed_cost - lower, abs(claimed_cost))
                and _close(camera.get("optimal_cost"), claim.get("cost"))):
            raise Invalid("returned", f"{where}: gap or optimal_cost is not what its cost and its proof give")
        if camera.get("status") != "optimal":
            raise Invalid("returned", f"{where}: a certified camera's status is optimal")
        tolerance = _camera_tolerance(camera, dof, len(source), norm, float(options["rel_gap"]), where)
        allowed = (1.0 + tolerance) * proven + float(options["abs_gap"])
        if not cost <= allowed * (1 + ROUNDING) + ROUNDING * max(1.0, abs(cost)):
            raise Invalid("returned", f"{where}: costs {cost:.6g}, beyond (1 + tolerance {tolerance:.3g}) times the "
                                      f"proven bound {proven:.6g} plus abs_gap")


def _camera_tolerance(camera: dict, dof: int, points: int, norm: str, rel_gap: float, where: str) -> float:
    """A certified camera's tolerance (camera_claim.tolerance), recomputed from its points, the
    norm, camera_rel_gap and its degrees of freedom, which the returned cameras' K give
    (camera_claim.degrees_of_freedom); the camera's stated figures must be these. A camera that
    states none (a result from before they were stated) is held to a 3x4 camera's: no allowance."""
    stated = camera.get("degrees_of_freedom")
    if stated is None and camera.get("tolerance") is None:
        dof = camera_claim.PROJECTIVE_DOF
    elif stated != dof:
        raise Invalid("returned", f"{where}: degrees_of_freedom {stated!r}, the returned cameras' K give {dof}")
    tolerance = camera_claim.tolerance(points, dof, norm, rel_gap)
    if tolerance is None:
        raise Invalid("returned", f"{where}: {points} points and camera_rel_gap {rel_gap!r} allow no tolerance")
    if "tolerance" in camera and not _close(camera["tolerance"], tolerance):
        raise Invalid("returned", f"{where}: tolerance {camera['tolerance']!r}, its points and degrees of freedom "
                                  f"give {tolerance!r}")
    return tolerance


class ReconstructionItems(TrackItems):
    """Points as triangulations (TrackItems), plus ``check_result``: the rest of the result."""

    @staticmethod
    def job_outcomes(result: dict) -> list:
        """One item, certified when it has points and every one is (its status is the job's own)."""
        points = result.get("points") or []
        return [(None, bool(points) and all(isinstance(p, dict) and p.get("certified") is True for p in points))]

    def checked_options(self, options: dict) -> dict:
        """The points' options (a triangulation's), and the cameras' tolerance (stated in the
        scope; the camera certificate hashes it as its rel_gap)."""
        from geocert.solvers.verify import residual_options

        checked = residual_options("reconstruction", options)
        if options.get("camera_rel_gap") is not None:
            checked["camera_rel_gap"] = number(options["camera_rel_gap"], "options/camera_rel_gap", "options")
        return checked

    def scope_statement(self, options: dict) -> dict:
        from geocert.solvers.verify import scope_statement

        statement = scope_statement("triangulation", options)
        statement["kind"] = "reconstruction"
        statement["camera_rel_gap"] = options.get("camera_rel_gap")
        statement["statement"] = (
            "for each certified point, in the cameras returned (the certificate's data): " + statement["statement"]
            + "; for each certified camera, by the camera certificate (a resection document over the returned points, "
              "with the result's norm, max_residual, abs_gap and camera_rel_gap): no 3x4 camera in front of every point "
              "costs less than its lower_bound, and the camera returned costs cost, at most (1 + tolerance) lower_bound "
              "+ abs_gap, its tolerance the allowance for its fewer degrees of freedom than a 3x4 camera's (what they "
              "cost at the 99.9% level under Gaussian noise: a statistical allowance, not a bound) and camera_rel_gap; "
              "summary.calibration is checked to be about the K returned; the metric upgrade's certification "
              "(autocalibration_certified, calibration.certified_K) is the pipeline's statement: no proof of it is "
              "carried here")
        return statement

    def check_result(self, result: dict, certificate: dict, verify: Callable[[dict], object]) -> None:
        registered, views = _check_cameras(result.get("cameras"), certificate.get("data", {}))
        _check_points(result.get("points"), certificate.get("data", {}).get("tracks"), views)
        if any("searched" in camera for camera in registered):
            for camera in registered:
                if camera.get("searched") is not True and (camera.get("certified") is not False
                                                           or camera.get("lower_bound") is not None):
                    raise Invalid("returned", f"cameras/{camera.get('view')}: claims a bound (certified or a lower "
                                              "bound) but was not searched: no map of the camera certificate backs it")
            searched = [camera for camera in registered if camera.get("searched") is True]
        else:  # a result from before ``searched`` was stated: every registered camera has a map
            searched = registered
        certified = [k for k, camera in enumerate(searched) if camera.get("certified") is True]
        _check_camera_certificate(result, certificate, searched, certified, verify)
        _check_summary(result, registered)
        _check_calibration(result, registered)


RECONSTRUCTION = ReconstructionItems()
