"""The reconstruction kind's verification adapter (numpy only).

Its claims are the points, each a triangulation in the cameras the certificate's data state, so
they are checked as the triangulation kind's are (TrackItems). What ties them to the result:
the cameras the certificate's data state must be the cameras the result returns, and every camera
the result calls certified must be backed by the camera certificate beside it (a resection
document over the returned points): that certificate valid, its map for the camera built from the
returned points, the returned camera's cost recomputed from it, every point in front of that
camera (the resection bound's scope), its lower bound no higher than the proven one, and its gap
within the resection's tolerance.

The camera certificate holds one map per *searched* camera (``searched``: the certified
resection ran for it), in view order: a camera no bound could certify is not searched (see
structure.resect_cameras) and claims no bound, so it has no map; a camera called certified, or
stating a lower bound, must be searched. Every searched camera's map must be built from the
returned points. (A result without ``searched`` on its cameras, from before it was stated, is
read as every registered camera searched.)"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from geocert.solvers.core.geometry import norm_cost
from geocert.solvers.core.strict import Invalid
from geocert.solvers.fractional.items import TrackItems

ROUNDING = 1e-9  # relative: what JSON round trips and a recomputed cost may differ by


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


class ReconstructionItems(TrackItems):
    """Points as triangulations (TrackItems), plus ``check_result``: the returned cameras."""

    def check_result(self, result: dict, certificate: dict, verify: Callable[[dict], object]) -> None:
        cameras = result.get("cameras")
        if not isinstance(cameras, list) or not all(isinstance(c, dict) for c in cameras):
            raise Invalid("returned", "the result's cameras must be a list of objects")
        registered = _views_of(cameras)
        stated = certificate.get("data", {}).get("cameras")
        if stated != [camera["P"] for camera in registered]:
            raise Invalid("returned", "the cameras the points are certified in are not the cameras returned")
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
        if not certified:
            return
        document = result.get("camera_certificate")
        if not isinstance(document, dict):
            raise Invalid("returned", "cameras are called certified without a camera certificate")
        report = verify(document)
        if not getattr(report, "valid", False):
            raise Invalid("returned", f"the camera certificate is invalid: {getattr(report, 'first_failure', None)}")
        claims, maps = document.get("items"), document.get("data", {}).get("maps")
        if not isinstance(claims, list) or not isinstance(maps, list) or len(claims) != len(searched) \
                or len(maps) != len(searched):
            raise Invalid("returned", f"the camera certificate must hold one map per searched camera ({len(searched)}, "
                                      "in view order)")
        expected = camera_maps(result.get("points") or [], [int(camera["view"]) for camera in searched])
        for k, camera in enumerate(searched):
            if maps[k] != expected[k]:
                raise Invalid("returned", f"cameras/{camera.get('view')}: the camera certificate's map is not the "
                                          "returned points")
        options = document.get("options", {})
        norm = result.get("norm")
        for k in certified:
            camera, claim = searched[k], claims[k]
            where = f"cameras/{camera.get('view')}"
            if claim.get("certified") is not True:
                raise Invalid("returned", f"{where}: called certified, but its resection is not")
            source = np.asarray(maps[k]["source"], dtype=float)
            target = np.asarray(maps[k]["target"], dtype=float)
            P = np.asarray(camera["P"], dtype=float)
            projected = np.hstack([source, np.ones((len(source), 1))]) @ P.T
            if not np.all(projected[:, 2] > 0):
                raise Invalid("returned", f"{where}: a point is behind the camera returned, outside the bound's scope")
            cost = norm_cost(target - projected[:, :2] / projected[:, 2:3], norm)
            claimed_cost, lower = camera.get("cost"), camera.get("lower_bound")
            if not isinstance(claimed_cost, (int, float)) or not isinstance(lower, (int, float)) \
                    or abs(cost - claimed_cost) > ROUNDING * max(1.0, abs(cost)):
                raise Invalid("returned", f"{where}: cost {claimed_cost!r}, but the returned camera costs {cost!r}")
            if lower > claim["lower_bound"] + ROUNDING * max(1.0, abs(claim["lower_bound"])):
                raise Invalid("returned", f"{where}: lower bound {lower!r} above the proven {claim['lower_bound']!r}")
            tolerance = max(float(options.get("abs_gap", 0.0)), float(options.get("rel_gap", 0.0)) * cost)
            if not cost - claim["lower_bound"] <= tolerance * (1 + ROUNDING) + ROUNDING * max(1.0, abs(cost)):
                raise Invalid("returned", f"{where}: costs {cost:.6g}, beyond the tolerance {tolerance:.3g} above the "
                                          f"proven bound {claim['lower_bound']:.6g}")
            if not math.isfinite(cost):
                raise Invalid("returned", f"{where}: the returned camera's cost is not finite")


RECONSTRUCTION = ReconstructionItems()
