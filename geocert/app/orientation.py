"""/v1/orient's work (solvers/orientation.py on a request's reconstruction), done in an
orientation process (app.processes), not in the API process.

At its budget (20 cameras x 200k points) one orientation decodes a 6.4 MB body, builds dense
cameras x points arrays and writes a result of the same size: some 700 MB and 6 s of CPU, most of
it holding the interpreter lock (the body's decoding and validation, the loops over points, the
answer's encoding). In a thread of the API process, two at once kept another key's GET /v1/jobs
waiting 2.7 s, and the API process kept the 1.3 GB it had grown to. Here the API process reads the
body's bytes and sends back the answer's.
"""

from __future__ import annotations

import json

import numpy as np

from geocert.app import processes
from geocert.app.errors import ApiProblem
from geocert.settings import get_settings, over_budget
from geocert.core.geometry import InputError, check_cameras

# What the route's model reads in place of the body (its validation is then cheap); the body itself
# is validated in the orientation process.
STAND_IN = json.dumps({"cameras": [np.eye(3, 4).tolist()], "points": [[0.0, 0.0, 1.0]]}).encode()


def ready() -> None:
    """An orientation process's first task: what an orientation imports, imported."""
    from geocert.app import schemas  # noqa: F401
    from geocert.solvers import orientation  # noqa: F401


def orient_body(body: bytes, environment: dict[str, str]) -> tuple:
    """In an orientation process: ("answer", the result's JSON bytes), or an error carried
    (processes.validated, processes.carried). The heap's free pages go back to the system after
    each (an orientation at the budget leaves some 700 MB free in it)."""
    from pydantic import TypeAdapter

    from geocert.app.schemas import OrientRequest, OrientResult

    processes.use(environment)
    try:
        request, error = processes.validated(TypeAdapter(OrientRequest), body)
        if error is not None:
            return error
        try:
            found = oriented(request)
        except Exception as exc:  # the errors a request answers with; anything else is a bug, raised
            return processes.carried_or_raised(exc)
        del request
        document = OrientResult.model_validate(found).model_dump(mode="json")
        return "answer", json.dumps(document, ensure_ascii=False, allow_nan=False, separators=(",", ":")).encode()
    finally:
        processes.give_back_memory()


def oriented(body) -> dict:
    """The orientation of a request's reconstruction (an OrientRequest), as OrientResult's fields."""
    from geocert.solvers.orientation import orient

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
