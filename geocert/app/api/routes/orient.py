"""Orienting a projective reconstruction (solvers/orientation.py): camera and point signs, and a
plane at infinity off the scene, so that certificates' scope "in front of every camera" means
what an uncalibrated user means. The work is done in an orientation process (app.orientation)."""

from __future__ import annotations

from fastapi import APIRouter, Depends, Request, Response
from fastapi.routing import APIRoute

from geocert.app import orientation, processes, shape
from geocert.app.api.deps import error_responses, rate_limited
from geocert.app.schemas import OrientRequest, OrientResult
from geocert.settings import get_settings


class StandInRoute(APIRoute):
    """The body read here (a large one's cameras times points checked from its shape first:
    app.shape) and kept for the orientation process; the route's model reads a stand-in."""

    def get_route_handler(self):
        handler = super().get_route_handler()

        async def route_handler(request: Request) -> Response:
            body = await shape.check_body(request, shape.orient_figures)
            request.state.orient_body = bytes(body) if body is not None else await request.body()
            request._body = orientation.STAND_IN
            return await handler(request)

        return route_handler


router = APIRouter(tags=["orientation"], dependencies=[Depends(rate_limited)], route_class=StandInRoute)
# As many processes as orientations may run at once (the VerificationGate on /v1/orient refuses more).
_POOL = processes.Pool(lambda: get_settings().max_concurrent_orientations or 2, orientation.ready,
                       "the process orienting this reconstruction")


@router.post("/v1/orient", response_model=OrientResult, responses=error_responses(400, 413, 415, 422, 503))
async def orient_reconstruction(body: OrientRequest, request: Request):
    """Fix the signs of a projective reconstruction's cameras and points so that every point is at
    positive depth in every camera that sees it, moving the plane at infinity off the scene when
    the signs alone cannot give every point a positive last coordinate. Pixels are unchanged.
    Submit triangulation jobs with the cameras returned. Answers at once (no job)."""
    raw = request.state.orient_body
    outcome = await _POOL.run(orientation.orient_body, raw, processes.environment())
    if outcome[0] != "answer":
        processes.raise_carried(outcome, raw)
    return Response(outcome[1], media_type="application/json")
