"""Orienting a projective reconstruction (solvers/orientation.py): camera and point signs, and a
plane at infinity off the scene, so that certificates' scope "in front of every camera" means
what an uncalibrated user means."""

from __future__ import annotations

import numpy as np
from fastapi import APIRouter, Depends, Request, Response
from fastapi.routing import APIRoute

from geocert.app import shape
from geocert.app.api.deps import error_responses, rate_limited
from geocert.settings import get_settings, over_budget
from geocert.app.errors import ApiProblem
from geocert.app.schemas import OrientRequest, OrientResult
from geocert.solvers.core.geometry import InputError, check_cameras
from geocert.solvers.orientation import orient

class ShapeCheckedRoute(APIRoute):
    """A large body's cameras times points checked from its shape before it is parsed (app.shape)."""

    def get_route_handler(self):
        handler = super().get_route_handler()

        async def route_handler(request: Request) -> Response:
            body = await shape.check_body(request, shape.orient_figures)
            if body is not None:
                request._body = bytes(body)
            return await handler(request)

        return route_handler


router = APIRouter(tags=["orientation"], dependencies=[Depends(rate_limited)], route_class=ShapeCheckedRoute)


@router.post("/v1/orient", response_model=OrientResult, responses=error_responses(400, 413, 415, 422))
def orient_reconstruction(body: OrientRequest):
    """Fix the signs of a projective reconstruction's cameras and points so that every point is at
    positive depth in every camera that sees it, moving the plane at infinity off the scene when
    the signs alone cannot give every point a positive last coordinate. Pixels are unchanged.
    Submit triangulation jobs with the cameras returned. Answers at once (no job)."""
    settings = get_settings()
    observations = sum(len(v) for v in body.views) if body.views is not None else len(body.cameras) * len(body.points)
    if len(body.points) > settings.max_items_per_job:
        raise ApiProblem(413, f"{len(body.points)} points exceed the limit of {settings.max_items_per_job} "
                              "(GEOCERT_MAX_ITEMS_PER_JOB)", "points")
    # The orientation works on dense cameras x points arrays, whichever pairs are observed.
    exceeded = over_budget({"view_points": (len(body.cameras) * len(body.points), "points")})
    if exceeded is not None:
        raise ApiProblem(413, *exceeded)
    if observations > settings.max_points_per_job:
        raise ApiProblem(413, f"{observations} observations exceed the limit of {settings.max_points_per_job} "
                              "(GEOCERT_MAX_POINTS_PER_JOB)", "views" if body.views is not None else "points")
    cameras = np.asarray(body.cameras, dtype=float)
    largest = np.abs(cameras).max(axis=(1, 2), keepdims=True)  # signs and pixels do not depend on scale
    cameras = check_cameras(cameras / np.where(largest > 0, largest, 1.0), "cameras")
    points = np.asarray([p + [1.0] if len(p) == 3 else p for p in body.points], dtype=float)
    scale = np.abs(points).max(axis=1)
    for j in np.flatnonzero(scale == 0):
        raise InputError(f"points/{j}", "the zero vector is not a point")
    if body.views is not None:
        if len(body.views) != len(points):
            raise InputError("views", f"has {len(body.views)} entries for {len(points)} points: one list per point")
        for j, cams in enumerate(body.views):
            for k, camera in enumerate(cams):
                if camera >= len(cameras):
                    raise InputError(f"views/{j}/{k}", f"camera index {camera} out of range 0..{len(cameras) - 1}")
            if len(set(cams)) != len(cams):
                raise InputError(f"views/{j}", "a camera appears twice")
    found = orient(cameras, points / scale[:, None], body.views)
    return {
        "cameras": found.cameras.tolist(), "points": found.points.tolist(),
        "camera_signs": found.camera_signs.tolist(), "point_signs": found.point_signs.tolist(),
        "transform": found.transform.tolist(), "frame_changed": found.frame_changed,
        "quasi_affine": found.quasi_affine, "centres_one_side": found.centres_one_side,
        "oriented": found.quasi_affine and not found.negative_depths,
        "negative_depths": [list(pair) for pair in found.negative_depths],
        "undetermined": [list(pair) for pair in found.undetermined],
    }
