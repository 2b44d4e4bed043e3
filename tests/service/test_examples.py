"""The example jobs in examples/ (README: "Examples"): each is what examples/generate.py writes,
each solved through a real service gives the right answer (against the scene's ground truth, or
a property that holds on any machine), and the service and `geocert solve` give the same answer.

The real-data examples (``generate.py --shared``) are written from ../shared/data where it exists
and checked as valid jobs; the ones that solve in seconds are solved through the service too."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np
import pytest

from geocert.core.determinacy import fixes

from tests.servers import cluster
from tests.support import ROOT, SHARED_DATA

EXAMPLES = ROOT / "examples"
REAL_DATA = SHARED_DATA
SERVICE_TIME_LIMIT_S = 600  # what a job may take under a loaded machine; they take seconds


def load_generator():
    spec = importlib.util.spec_from_file_location("examples_generate", EXAMPLES / "generate.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


generate = load_generator()
NAMES = list(generate.EXAMPLES)


def close(a, b, rtol=1e-6, atol=1e-6) -> bool:
    """Two JSON documents equal but for numbers within a tolerance (a machine's BLAS may write
    the last digits of a generated scene differently)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(close(a[k], b[k], rtol, atol) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(close(x, y, rtol, atol) for x, y in zip(a, b))
    if isinstance(a, (int, float)) and not isinstance(a, bool) and isinstance(b, (int, float)) and not isinstance(b, bool):
        return abs(a - b) <= atol + rtol * abs(b)
    return a == b


class TestTheFiles:
    def test_every_kind_has_an_example_and_each_file_is_what_generate_writes(self):
        from geocert.kinds import KINDS

        kinds = {json.loads(generate.path(name).read_text())["kind"] for name in NAMES}
        assert kinds == set(KINDS.names())
        for name in NAMES:
            job, _ = generate.build(name)
            written = json.loads(generate.path(name).read_text())
            if name == "reconstruction-photos":  # JPEG bytes depend on the encoder's build: the rest must agree
                assert len(written["data"]["images"]) == len(job["data"]["images"])
                written["data"], job["data"] = None, None
            assert close(written, job), f"examples/{name}.json is stale: run .venv/bin/python examples/generate.py {name}"

    def test_each_file_is_a_valid_job(self):
        from geocert.app.schemas import JOB_REQUEST
        from geocert.jobs.runner import parse_job

        for name in NAMES:
            body = json.loads(generate.path(name).read_text())
            parse_job(JOB_REQUEST.dump_python(JOB_REQUEST.validate_python(body), mode="json"))


def test_the_openapi_document_carries_an_example_job_per_kind():
    """Swagger UI's "Examples" menu of POST /v1/jobs: each kind's own small example (the one
    GET /v1/problems gives and the page's template is), valid as it stands."""
    from geocert.app.schemas import JOB_REQUEST
    from geocert.kinds import KINDS

    spec = json.loads((ROOT / "openapi" / "openapi.json").read_text())
    examples = spec["paths"]["/v1/jobs"]["post"]["requestBody"]["content"]["application/json"]["examples"]
    assert set(examples) == set(KINDS.names())
    for kind in KINDS:
        assert examples[kind.name]["value"] == json.loads(json.dumps(kind.example))
        JOB_REQUEST.validate_python(examples[kind.name]["value"])


@pytest.mark.shared_data("oxford_house", "oxford_dinosaur", "middlebury_dinoSparseRing")
def test_the_real_data_examples_are_written_from_the_datasets(tmp_path, monkeypatch):
    from geocert.app.schemas import JOB_REQUEST
    from geocert.jobs.runner import parse_job

    monkeypatch.setattr(generate, "HERE", tmp_path)
    assert generate.main(["--shared", str(REAL_DATA)] + list(generate.REAL)) == 0
    for name in generate.REAL:
        body = json.loads((tmp_path / "real" / f"{name}.json").read_text())
        parse_job(JOB_REQUEST.dump_python(JOB_REQUEST.validate_python(body), mode="json"))


# --- solved through a real service, and by the CLI ---------------------------------------------

@pytest.fixture(scope="module")
def service(tmp_path_factory):
    with cluster(tmp_path_factory.mktemp("examples"), workers=1) as (_, client):
        yield client


def solve_through_service(client: httpx.Client, body: dict) -> dict:
    response = client.post("/v1/jobs", json=body)
    assert response.status_code == 202, response.text
    job_id = response.json()["id"]
    deadline = time.monotonic() + SERVICE_TIME_LIMIT_S
    while (job := client.get(f"/v1/jobs/{job_id}").json())["status"] not in ("succeeded", "failed", "cancelled"):
        assert time.monotonic() < deadline, f"job still {job['status']}"
        time.sleep(0.2)
    assert job["status"] == "succeeded", job.get("error")
    return job["result"]


def solve_by_cli(path: Path) -> dict:
    run = subprocess.run([sys.executable, "-m", "geocert.app.cli", "solve", "--compact", str(path)],
                         capture_output=True, text=True, timeout=SERVICE_TIME_LIMIT_S)
    assert run.returncode == 0, run.stderr
    return json.loads(run.stdout)


ITEM_LISTS = ("tracks", "maps", "frames", "stages", "points", "pairs")


def same_answer(a: dict, b: dict) -> None:
    """The two paths' results agree: every item's status and certified flag; a certified item's
    cost within its certificate's tolerance of the other's (both lie between the same optimum
    and its bound plus the tolerance); estimates and cameras within rounding."""
    assert a["kind"] == b["kind"]
    for key in ITEM_LISTS:
        if not isinstance(a.get(key), list) or not all(isinstance(x, dict) for x in a[key]):
            continue  # (an autocalibration's points are coordinates, not items)
        assert len(a[key]) == len(b[key]), key
        for x, y in zip(a[key], b[key]):
            assert (x.get("status"), x.get("certified")) == (y.get("status"), y.get("certified")), (key, x, y)
            if x.get("certified") and x.get("cost") is not None:
                tolerance = max((x.get("certificate") or {}).get("tolerance") or 0,
                                (y.get("certificate") or {}).get("tolerance") or 0)
                assert abs(x["cost"] - y["cost"]) <= tolerance * (1 + 1e-9) + 1e-12, (key, x["cost"], y["cost"], tolerance)
            for field in ("R", "t"):
                if isinstance(x.get(field), list):
                    assert np.allclose(x[field], y[field], atol=1e-6), (key, field)
    if a["kind"] == "reconstruction":
        assert a["summary"]["views_registered"] == b["summary"]["views_registered"]
        assert [c["certified"] for c in a["cameras"]] == [c["certified"] for c in b["cameras"]]


# ground truth and properties, per example

def reprojection_cost(P, X, pixels, squared=True) -> float:
    x = np.asarray(P) @ np.append(X, 1.0)
    d = np.linalg.norm(x[:2] / x[2] - pixels)
    return d * d if squared else d


def map_cost(M, source, target, squared) -> float:
    source, target = np.asarray(source), np.asarray(target)
    x = np.c_[source, np.ones(len(source))] @ np.asarray(M).T
    d = np.linalg.norm(x[:, :-1] / x[:, -1:] - target, axis=1)
    return float((d * d).sum() if squared else d.sum())


def up_to_scale(M, truth) -> float:
    M, truth = np.asarray(M) / np.linalg.norm(M), np.asarray(truth) / np.linalg.norm(truth)
    return min(np.linalg.norm(M - truth), np.linalg.norm(M + truth))


def rotation_degrees(R, truth) -> float:
    c = (np.trace(np.asarray(R).T @ np.asarray(truth)) - 1) / 2
    return float(np.degrees(np.arccos(np.clip(c, -1, 1))))


def check_triangulation(job, truth, result):
    cameras = job["data"]["cameras"]
    for track, X, item in zip(job["data"]["tracks"], truth["points"], result["tracks"]):
        assert item["certified"]
        at_truth = sum(reprojection_cost(cameras[v], X, p) for v, p in zip(track["views"], track["points"]))
        assert item["cost"] <= at_truth + item["certificate"]["tolerance"]  # the optimum is no worse than the truth
        assert item["lower_bound"] <= at_truth
        assert np.linalg.norm(np.asarray(item["point"]) - X) < 0.3  # 1 px of noise, a unit cloud 8 away, 2 views or more


def check_maps(job, truth, result):
    squared = job["options"]["norm"] == "L2L2"
    for entry, T, item in zip(job["data"]["maps"], truth["matrices"], result["maps"]):
        assert item["certified"]
        assert abs(map_cost(item["matrix"], entry["source"], entry["target"], squared) - item["cost"]) <= 1e-6 * item["cost"]
        at_truth = map_cost(T, entry["source"], entry["target"], squared)
        assert item["lower_bound"] <= at_truth and item["cost"] <= at_truth + item["certificate"]["tolerance"]
        assert up_to_scale(item["matrix"], T) < 0.05


def check_autocalibration(job, truth, result):
    assert all(stage["certified"] for stage in result["stages"])
    K, true_K = np.asarray(result["K"]), np.asarray(truth["K"])
    assert abs(K[0, 0] / true_K[0, 0] - 1) < 0.02 and abs(K[1, 1] / true_K[1, 1] - 1) < 0.02
    assert np.abs(K[:2, 2] - true_K[:2, 2]).max() < 20  # pixels, of a 1000 px image at 0.1% noise
    entries = {"focal_x": (0, 0), "focal_y": (1, 1), "skew": (0, 1), "principal_u": (0, 2), "principal_v": (1, 2)}
    for stage in result["stages"]:
        determinacy = stage["determinacy"]
        assert determinacy["warnings"] == []  # a general motion: nothing critical, nothing cut by a range
        assert determinacy["determined"] == all(fixes(i) for i in determinacy["intervals"])
        K_intervals = [i for i in determinacy["intervals"] if i["name"] in entries]
        # the focal lengths bounded within a fifth of their value; since the stratified intervals
        # hold the views' delete-one jackknife (form 2: the reference view's noise), six views fix
        # neither them within a tenth (858 to 1143 px about 1000) nor the principal point
        for found in (i for i in K_intervals if i["name"].startswith("focal")):
            assert found["lower"] is not None and found["upper"] is not None, found
            assert found["upper"] - found["lower"] < 0.4 * found["value"], found
        for found in K_intervals:  # every bounded interval holds the truth
            true = true_K[entries[found["name"]]]
            assert found["lower"] is None or found["lower"] <= true, found
            assert found["upper"] is None or true <= found["upper"], found


def check_turntable(job, truth, result):
    """A critical motion: whatever the search reached, the result says K is not determined."""
    for stage in result["stages"]:
        assert "orbital_motion" in [w["code"] for w in stage["determinacy"]["warnings"]]
        assert stage["determinacy"]["determined"] is False


def check_bilinear(job, truth, result):
    basis = np.asarray(job["data"]["basis"])
    for frame, true, item in zip(job["data"]["frames"], truth["frames"], result["frames"]):
        assert item["certified"]
        seen = [k for k, p in enumerate(frame["points"]) if p is not None]
        points = np.asarray([frame["points"][k] for k in seen])
        camera = np.asarray(true["camera"])
        shape = np.tensordot(true["coefficients"], basis, axes=1)[seen]
        at_truth = float(((shape @ camera[:, :3].T + camera[:, 3] - points) ** 2).sum())
        assert item["lower_bound"] <= at_truth and item["cost"] <= at_truth + item["certificate"]["tolerance"]
        assert np.abs(np.asarray(item["coefficients"]) - true["coefficients"]).max() < 0.1


def check_stereo(job, truth, result):
    pair = result["pairs"][0]
    assert pair["status"] == "estimate" and pair["certified"] is False
    assert rotation_degrees(pair["R"], truth["R"]) < 0.5  # of a 3 degree turn, 0.3 px of noise
    # metres, of an 8 cm step: 20 lines 2 to 6 m away from a 7.4 cm baseline fix t to about a centimetre
    assert np.linalg.norm(np.asarray(pair["t"]) - truth["t"]) < 0.03


def check_reconstruction(job, truth, result):
    from testing.reconstruction import aligned_rotation_errors

    registered = [c for c in result["cameras"] if c["registered"]]
    assert len(registered) == len(truth["rotations"])
    assert result["summary"]["points_certified_fraction"] == 1.0
    errors = aligned_rotation_errors([np.asarray(c["R"]) for c in registered], [np.asarray(R) for R in truth["rotations"]])
    assert errors.max() < 1.0  # degrees
    assert abs(registered[0]["K"][0][0] / truth["K"][0][0] - 1) < 0.03


CHECKS = {
    "triangulation": check_triangulation,
    "resection": check_maps,
    "homography-plane": check_maps,
    "homography-space": check_maps,
    "autocalibration-stratified": check_autocalibration,
    "autocalibration-direct": check_autocalibration,
    "autocalibration-turntable": check_turntable,
    "bilinear": check_bilinear,
    "stereo-lines-pair": check_stereo,
    "reconstruction-tracks": check_reconstruction,
    "reconstruction-photos": check_reconstruction,
}


def test_every_example_has_its_check():
    assert set(CHECKS) == set(NAMES)


def test_the_examples_readme_says_what_each_exercises_and_the_turntable_names_its_warning():
    """examples/README.md has a line for every example; the turntable's names the warning its
    result carries (check_turntable), so a newcomer reading the folder knows it is there to show
    ``orbital_motion``, the critical motion warning."""
    rows = {line.split("`")[1]: line for line in (EXAMPLES / "README.md").read_text().splitlines()
            if line.startswith("| `")}
    assert set(rows) == {f"{name}.json" for name in NAMES}
    assert "`orbital_motion`" in rows["autocalibration-turntable.json"]
    assert "critical motion" in rows["autocalibration-turntable.json"]
    assert "orbital_motion" in generate.autocalibration_turntable.__doc__.split(".")[0]


@pytest.mark.slow  # a real service and a CLI run per example
@pytest.mark.parametrize("name", NAMES)
def test_the_service_solves_the_example_and_the_cli_gives_the_same_answer(service, name):
    path = generate.path(name)
    job = json.loads(path.read_text())
    _, truth = generate.build(name)
    result = solve_through_service(service, job)
    CHECKS[name](job, truth, result)
    same_answer(result, solve_by_cli(path))


@pytest.mark.slow
@pytest.mark.shared_data("oxford_house")
def test_the_real_house_triangulation_through_the_service_and_the_cli(service, tmp_path):
    """The Oxford Model House's tracks in VGG's cameras (credit: Oxford VGG)."""
    path = tmp_path / "house-triangulation.json"
    path.write_text(json.dumps(generate.house_triangulation(REAL_DATA)))
    result = solve_through_service(service, json.loads(path.read_text()))
    assert result["stats"]["items"] == len(json.loads(path.read_text())["data"]["tracks"])
    for track in result["tracks"]:
        assert track["cost"] is None or track["lower_bound"] is None or track["lower_bound"] <= track["cost"] * (1 + 1e-9)
    same_answer(result, solve_by_cli(path))
