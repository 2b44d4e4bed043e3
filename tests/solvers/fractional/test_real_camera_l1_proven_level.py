"""An L1 resection's proven intervals on real cameras are proven at the level its estimate is read
at, the Student quantile of its degrees of freedom (issue 37). At 3^2 times the residual variance
whatever the degrees of freedom, 7-point L1L1 resections of the Middlebury dino's hemisphere
cameras at 0.1 px had a proven centre box missing the true centre where the estimate beside it
held it: 4 of the first 120 cameras, 1 of templeSparseRing's 48 (3 draws of 16), because with 3
degrees of freedom (2k - 11) 3^2 is about a ninth of the Student level.

The verifier holds a form-2 document to the same level: one proven at 3^2 is refused."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.core.determinacy import level_sigmas
from geocert.jobs.runner import solve_job
from geocert.solvers import datasets
from geocert.verify.checks import verify_any

from tests.support import dino_hemisphere_cameras, shared_data


POINTS, NOISE_PX = 7, 0.1
CHOSEN = range(60)  # the hemisphere's first 60 cameras: at 3^2, cameras 32, 36 and 40 missed


def resections(views: datasets.CalibratedViews, chosen) -> list[tuple[dict, np.ndarray]]:
    """(job, true centre) of L1L1 resections of the cameras ``chosen`` of ``views``, each from
    POINTS points drawn in the set's box that the camera sees, reprojected with NOISE_PX of noise
    (each job's draw its own, seeded by its index)."""
    lower, upper = views.box
    width, height = views.image_size
    jobs = []
    for k in chosen:
        camera, centre = views.cameras[k], views.centres[k]
        rng = np.random.default_rng((37, int(k)))
        X = rng.uniform(lower, upper, size=(40 * POINTS, 3))
        proj = np.hstack([X, np.ones((len(X), 1))]) @ camera.T
        image = proj[:, :2] / proj[:, 2:3]
        seen = (proj[:, 2] > 0) & np.all((image >= 0) & (image <= [width, height]), axis=1)
        X, image = X[seen][:POINTS], image[seen][:POINTS] + rng.normal(scale=NOISE_PX, size=(POINTS, 2))
        jobs.append(({"kind": "resection", "data": {"maps": [{"source": X.tolist(), "target": image.tolist()}]},
                      "options": {"certificate": "full", "norm": "L1L1"}}, centre))
    return jobs


def holds(intervals: list[dict], centre: np.ndarray) -> bool:
    return all(i["lower"] is not None and i["upper"] is not None and i["lower"] <= c <= i["upper"]
               for i, c in zip(intervals, centre))


@pytest.mark.slow
@pytest.mark.parametrize("points, centres_proven", [(7, 10), (8, 55)])
def test_a_proven_box_holds_the_true_centre_wherever_the_estimate_does(monkeypatch, points, centres_proven):
    """At 3^2, cameras 32, 36 and 40 (7 points) and two others (8 points) of these 60 missed. At
    the Student level the centre's proof (resection_centre_l1, an enclosure at the level) is found
    less often with 7 points, where the level is about 9 times 3^2's (22 of 60 here, against 60);
    the depth rows are proven for all 60 whatever the points."""
    monkeypatch.setitem(globals(), "POINTS", points)
    missed, proven, rows = [], 0, 0  # missed: (resection, the estimate's level, the proven one)
    for k, (job, centre) in enumerate(resections(dino_hemisphere_cameras(), CHOSEN)):
        d = solve_job(job)["maps"][0]["determinacy"]
        estimate = [next(i for i in d["intervals"] if i["name"] == q) for q in ("centre_x", "centre_y", "centre_z")]
        named = {i["name"]: i for i in (d["proven_intervals"] or {}).get("intervals", [])}
        rows += "depth_x" in named
        if "centre_x" not in named:  # the centre not proven (resection_centre_l1): nothing to hold
            continue
        proven += 1
        box = [named[q] for q in ("centre_x", "centre_y", "centre_z")]
        if holds(estimate, centre) and not holds(box, centre):
            missed.append((k, d["cost_increase"], d["proven_intervals"]["cost_increase"]))
    assert missed == [] and rows == len(CHOSEN) and proven >= centres_proven, (missed, rows, proven)


def test_the_level_is_the_students_and_the_verifier_holds_a_document_to_it():
    """The proven level is at least the Student quantile's (2k - 11 = 3 degrees of freedom) times
    the L1 counterpart of the residual variance; a document proven at 3^2 is refused."""
    from unittest import mock

    from geocert.formulations.fractional import resection_leaves

    job, _ = resections(datasets.load_middlebury(shared_data("middlebury_dinoSparseRing")), [0])[0]
    result = solve_job(job)
    item = result["maps"][0]
    proven = item["determinacy"]["proven_intervals"]
    assert proven is not None
    dof = 2 * POINTS - 11
    student = level_sigmas(dof) ** 2 / 2 * item["cost"] / dof
    assert proven["cost_increase"] >= student * (1 - 1e-9)
    assert verify_any(result).valid

    def three_squared(norm, cost, points, gap):  # forms 0 and 1's level
        redundancy = 2 * points - 11
        delta = (9.0 / 2 if norm == "L1L1" else 9.0) * cost / redundancy
        return max(delta, gap) if gap is not None and np.isfinite(gap) else delta

    with mock.patch("geocert.solvers.fractional.maps.l1_cost_increase", three_squared):
        old = solve_job(job)
    assert old["maps"][0]["determinacy"]["proven_intervals"]["cost_increase"] < student
    report = verify_any(old)
    assert not report.valid and "l1_cost_increase" in str(report.first_failure)
    assert resection_leaves.l1_cost_increase("L1L1", 1.0, POINTS, None) >= level_sigmas(dof) ** 2 / 2 / dof * (1 - 1e-12)
