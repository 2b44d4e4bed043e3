"""One client cannot hurt the service or another client (issue 36): each defect a hostile client
reproduced, against real servers (embedded Redis, the API and Celery workers, each a process),
with limits set small through the settings so that no test needs a real bomb. Webhook tests send
nothing anywhere but 127.0.0.1: a refused destination is refused before any connection."""

from __future__ import annotations

import base64
import io
import json
import os
import signal
import socket
import threading
import time
import zipfile
from pathlib import Path

import cv2
import httpx
import numpy as np
import pytest
import redis

from testing.receivers import Receiver
from geocert.solvers.autocalibration import scenes
from geocert.workers.priorities import queue_lists
from tests.servers import cluster, spawned

pytestmark = pytest.mark.slow  # real servers: the full run only

TERMINAL = ("succeeded", "failed", "cancelled")
TRIANGULATION = {"kind": "triangulation", "data": {
    "cameras": [[[800, 0, 320, 0], [0, 800, 240, 0], [0, 0, 1, 0]], [[800, 0, 320, -800], [0, 800, 240, 0], [0, 0, 1, 0]]],
    "tracks": [{"views": [0, 1], "points": [[330, 250], [250, 251]]}]}}


def ended(client, job_id: str, limit_s: float = 240, headers: dict | None = None) -> dict:
    deadline = time.monotonic() + limit_s
    while (job := client.get(f"/v1/jobs/{job_id}", headers=headers).json())["status"] not in TERMINAL:
        assert time.monotonic() < deadline, f"job still {job['status']} after {limit_s} s"
        time.sleep(0.2)
    return job


def waiting_tasks(store: redis.Redis) -> int:
    return sum(store.llen(name) for name in queue_lists("celery"))


def problem(response, status: int) -> dict:
    assert response.status_code == status, response.text
    assert response.headers["content-type"].startswith("application/problem+json")
    return response.json()


def png(width: int, height: int) -> str:
    ok, data = cv2.imencode(".png", np.zeros((height, width), np.uint8))
    assert ok
    return base64.b64encode(data.tobytes()).decode()


def photos(*contents: str) -> dict:
    return {"kind": "reconstruction", "data": {"images": [{"name": f"p{i}", "content": c} for i, c in enumerate(contents)]}}


def long_autocalibration(time_limit_s: float) -> dict:
    """Four cameras without points: neither stage closes its gap, each runs to its time limit."""
    data = scenes.make_scene(4, 0.1, seed=5).job_data()
    data.pop("points")
    return {"kind": "autocalibration", "data": data, "options": {"time_limit_s": time_limit_s, "max_nodes": 100_000}}


def peak_rss_mib(pid: int) -> float:
    with open(f"/proc/{pid}/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmHWM:")) / 1024


def job_keys(store: redis.Redis, job_id: str) -> list[str]:
    return list(store.scan_iter(f"geocert:job:{job_id}*"))


class Listener:
    """A loopback socket that counts the connections made to it (answering none)."""

    def __init__(self):
        self.socket = socket.socket()
        self.socket.bind(("127.0.0.1", 0))
        self.socket.listen(16)
        self.socket.settimeout(0.2)
        self.port, self.connections, self.stopped = self.socket.getsockname()[1], 0, False
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self):
        while not self.stopped:
            try:
                connection, _ = self.socket.accept()
                self.connections += 1
                connection.close()
            except OSError:
                continue

    def close(self):
        self.stopped = True
        self.socket.close()


def first_delivery(client, receiver) -> str:
    """A small job whose callback is ``receiver``: its id, once it has ended and its webhook's
    first attempt has reached the receiver."""
    job_id = client.post("/v1/jobs", json={**TRIANGULATION, "callback_url": receiver.url}).json()["id"]
    ended(client, job_id)
    deadline = time.monotonic() + 60
    while receiver.received == 0:
        assert time.monotonic() < deadline, "no delivery attempt"
        time.sleep(0.05)
    return job_id


# ---------------------------------------------------------------------------------------------
# A server with its default limits and no webhook destinations allowed beyond public ones


def held_by_gate(client: httpx.Client, gate: str, count: int) -> None:
    """Wait until the API process's ``gate`` holds ``count`` requests (its /metrics gauge): what a
    test sends after that meets the gate full, whatever the machine's load."""
    line = f'geocert_gated_requests{{gate="{gate}"}} '
    guard = time.monotonic() + 600  # against a hang only: no outcome depends on it
    while (held := next((float(row[len(line):]) for row in client.get("/metrics").text.splitlines()
                         if row.startswith(line)), 0.0)) < count:
        assert time.monotonic() < guard, f"the {gate} gate holds {held:g} requests, not {count}"
        time.sleep(0.05)
    assert held == count, f"the {gate} gate holds {held:g} requests, not {count}"


@pytest.fixture(scope="module")
def plain(tmp_path_factory):
    with cluster(tmp_path_factory.mktemp("plain"), workers=1) as (running, client):
        yield running, client


def test_1_photo_bombs_are_refused_from_their_headers_without_the_api_decoding_them(plain):
    """20 blank PNGs of 5000x5000 (each within the per-image limits of the decoder) in a 0.9 MB
    body: the API decoded them all before queueing (+500 MB; 100 of them, +2.4 GB). Now their
    pixels are read from their headers and the job refused (413 naming the figure and the limit);
    a truncated JPEG whose header claims 3000x3000 is refused as unable to fill it (its decoder
    filled the missing data with grey), and the API's peak memory barely moves."""
    running, client = plain
    before = peak_rss_mib(running.api.pid)
    bomb = png(5000, 5000)
    answer = problem(client.post("/v1/jobs", json=photos(*[bomb] * 20)), 413)
    assert "500000000 pixels" in answer["detail"] and "GEOCERT_MAX_IMAGE_PIXELS" in answer["detail"]
    assert answer["errors"][0]["field"].startswith("data/images")
    ok, jpeg = cv2.imencode(".jpg", np.random.default_rng(0).integers(0, 255, (3000, 3000), dtype=np.uint8))
    truncated = base64.b64encode(jpeg.tobytes()[:4000]).decode()
    answer = problem(client.post("/v1/jobs", json=photos(png(64, 64), truncated)), 422)
    assert answer["errors"][0]["field"] == "data/images/1/content" and "cannot fill" in answer["detail"]
    assert peak_rss_mib(running.api.pid) - before < 100


def test_5_6_a_large_body_over_budget_is_refused_from_its_shape_unparsed(plain):
    """A body is parsed into Python objects some 25 times its size, and a job or /v1/orient
    request over its budget was refused only once parsed (a 6.5 MB /v1/orient body: 0.65 s of the
    API's CPU; 32 MiB: several seconds and gigabytes). Now a large body's figures are read from
    its shape (its arrays' lengths; app.shape) and it is refused before any of its numbers is
    built: 6.5 MB of /v1/orient points and 20 MB of a bilinear basis barely move the API's peak
    memory (it grew by hundreds of MiB).
    The refusal names the figure as before; a body within budget is parsed and answered as ever."""
    running, client = plain
    rng = np.random.default_rng(3)
    cameras = np.round(rng.normal(size=(300, 3, 4)), 4).tolist()
    points = np.round(rng.normal(size=(200_000, 3)), 3).tolist()
    before = peak_rss_mib(running.api.pid)
    answer = problem(client.post("/v1/orient", json={"cameras": cameras, "points": points}, timeout=300), 413)
    assert "60000000 views times points" in answer["detail"] and "GEOCERT_MAX_VIEW_POINTS_PER_JOB" in answer["detail"]
    assert answer["errors"][0]["field"] == "points"
    basis = np.round(rng.normal(size=(2000, 400, 3)), 3).tolist()
    job = {"kind": "bilinear", "data": {"basis": basis, "frames": [{"points": [[0.0, 0.0]] * 400}]}}
    answer = problem(client.post("/v1/jobs", json=job, timeout=300), 413)
    assert "800000 basis shapes times points" in answer["detail"] and answer["errors"][0]["field"] == "data/basis"
    assert peak_rss_mib(running.api.pid) - before < 100
    small = client.post("/v1/orient", json={"cameras": cameras[:2], "points": points[:5000]})
    assert small.status_code == 200, small.text


def test_6_orientations_at_once_are_bounded(plain):
    """/v1/orient is computed in the API process: at its budget (20 cameras x 200k points) one
    request held some 700 MB and 12 s of CPU, and four at once took the API to 3 GB while another
    key's GET /v1/jobs waited 5 s; nothing bounded how many ran at once. Now a third is refused
    (429 with Retry-After, naming GEOCERT_MAX_CONCURRENT_ORIENTATIONS) while two are running,
    counted from before the body is read: here two requests whose bodies are still arriving."""
    running, client = plain
    body = json.dumps({"cameras": [np.eye(3, 4).tolist()] * 2, "points": [[0.0, 0.0, 1.0]] * 10}).encode()
    # The orientation processes start with the first (seconds): started before the count is read.
    assert client.post("/v1/orient", content=body, headers={"content-type": "application/json"}).status_code == 200
    release, results = threading.Event(), []

    def held_body():
        yield body[:10]
        release.wait(20)
        yield body[10:]

    def held_request():
        with httpx.Client(base_url=running.base, timeout=60) as own:
            results.append(own.post("/v1/orient", content=held_body(),
                                    headers={"content-type": "application/json"}).status_code)

    held = [threading.Thread(target=held_request) for _ in range(2)]
    try:
        for thread in held:
            thread.start()
        held_by_gate(client, "orientations", 2)  # a third sent before they arrived would be let in, rightly
        third = client.post("/v1/orient", content=body, headers={"content-type": "application/json"})
        assert "GEOCERT_MAX_CONCURRENT_ORIENTATIONS" in problem(third, 429)["detail"]
    finally:
        release.set()
        for thread in held:
            thread.join(60)
    assert results == [200, 200]
    assert client.post("/v1/orient", content=body, headers={"content-type": "application/json"}).status_code == 200


def test_6_orientations_run_outside_the_api_process(plain):
    """/v1/orient decoded its body, built its dense arrays and wrote its answer in the API process,
    holding the interpreter lock for most of it: two at the budget kept another client's GET
    /v1/jobs waiting 2.5-3.3 s, and the API kept the 1.3-2.0 GB it grew to. Now the orientation is
    done in an orientation process: with that process stopped (SIGSTOP) while it holds a request,
    another request is answered and the orientation is not, and it ends once the process runs
    again with the answer it gives in process; errors read as they did; a killed orientation
    process fails the request it held with a 503, and the next is taken."""
    running, client = plain
    rng = np.random.default_rng(6)
    body = {"cameras": rng.normal(size=(3, 3, 4)).tolist(), "points": rng.normal(size=(40, 3)).tolist()}
    first = client.post("/v1/orient", json=body)  # starts the orientation processes, and waits for them
    assert first.status_code == 200, first.text
    helpers = spawned(running.api.pid)
    assert helpers, "no orientation process: the orientation ran in the API process"
    for pid in helpers:
        os.kill(pid, signal.SIGSTOP)
    answered = {}
    try:
        sender = threading.Thread(target=lambda: answered.update(answer=client.post("/v1/orient", json=body, timeout=120)))
        sender.start()
        assert client.get("/v1/jobs").status_code == 200
        sender.join(timeout=5)  # an answer now could only come from the API process itself
        assert sender.is_alive(), "the orientation was answered while its process was stopped"
    finally:
        for pid in helpers:
            os.kill(pid, signal.SIGCONT)
    sender.join(timeout=120)
    assert answered["answer"].status_code == 200 and answered["answer"].json() == first.json()
    refused = client.post("/v1/orient", json={**body, "points": [[0, 0, 0, 0]]})
    assert refused.status_code == 422 and refused.json()["errors"][0]["field"] == "points/0", refused.text
    invalid = client.post("/v1/orient", json={**body, "cameras": "many"})
    assert invalid.status_code == 422 and invalid.json()["errors"][0]["field"] == "cameras", invalid.text
    broken = client.post("/v1/orient", content=json.dumps(body)[:-2].encode() + b"x}",
                         headers={"content-type": "application/json"})
    assert broken.status_code == 400, broken.text
    assert client.post("/v1/orient", content=json.dumps(body), headers={"content-type": "text/plain"}).status_code == 415
    for pid in spawned(running.api.pid):
        os.kill(pid, signal.SIGKILL)
    lost = client.post("/v1/orient", json=body)
    assert lost.status_code == 503 and lost.headers["Retry-After"], lost.text
    again = client.post("/v1/orient", json=body)
    assert again.status_code == 200 and again.json() == first.json()


def test_verifications_run_outside_the_api_process(plain):
    """A certificate verification read and checked its document in a thread of the API process,
    holding the interpreter lock for seconds: two of 26 MB at once kept another client's GET
    /v1/jobs waiting 2.4-2.8 s. Now it runs in a verification process: with that process stopped
    while it holds a document, another request is answered and the verification is not; it ends
    once the process runs again, with the report it gives in process; errors read as they did."""
    running, client = plain
    document = {"kind": "triangulation", "items": [[0.5] * 10] * 20}
    first = client.post("/v1/certificates/verify", json=document)  # starts the processes, and waits for them
    assert first.status_code == 200 and first.json()["valid"] is False, first.text
    before = set(spawned(running.api.pid))
    helpers = list(before)
    assert helpers, "no verification process: the verification ran in the API process"
    for pid in helpers:
        os.kill(pid, signal.SIGSTOP)
    answered = {}
    try:
        sender = threading.Thread(target=lambda: answered.update(
            answer=client.post("/v1/certificates/verify", json=document, timeout=120)))
        sender.start()
        assert client.get("/v1/jobs").status_code == 200
        sender.join(timeout=5)  # an answer now could only come from the API process itself
        assert sender.is_alive(), "the verification was answered while its process was stopped"
    finally:
        for pid in helpers:
            os.kill(pid, signal.SIGCONT)
    sender.join(timeout=120)
    assert answered["answer"].status_code == 200 and answered["answer"].json() == first.json()
    broken = client.post("/v1/certificates/verify", content=b'{"kind": x}', headers={"content-type": "application/json"})
    assert broken.status_code == 400 and broken.headers["content-type"].startswith("application/problem+json")
    twice = client.post("/v1/certificates/verify", content=b'{"kind": 1, "kind": 2}',
                        headers={"content-type": "application/json"})
    assert twice.status_code == 422 and twice.json()["errors"][0]["field"] == "kind", twice.text


def test_a_map_over_its_points_budget_is_refused_at_submission(plain):
    """One map of 200,000 points (within the job's items and observations) was queued: its
    first conic programs ignore the time limit (2 s asked; 20,000 points ran 65 s), and a solver
    process held 3.3 GB before it died. The points of one map are a budget figure: 413 naming
    it, read from a large body's shape (a small one's: test_a_map_at_its_points_budget_is_taken)."""
    _, client = plain
    rng = np.random.default_rng(4)
    source = np.round(rng.normal(size=(20_001, 3)), 6).tolist()
    target = np.round(rng.uniform(0, 640, size=(20_001, 2)), 3).tolist()
    job = {"kind": "resection", "data": {"maps": [{"source": source[:10], "target": target[:10]},
                                                  {"source": source, "target": target}]}}
    answer = problem(client.post("/v1/jobs", json=job), 413)
    assert "20001 points in one map" in answer["detail"] and "GEOCERT_MAX_POINTS_PER_MAP" in answer["detail"]
    assert answer["errors"][0]["field"] == "data/maps/1/source"
    job = {"kind": "homography", "data": {"maps": [{"source": [p[:2] for p in source[:20_001]], "target": target}]}}
    answer = problem(client.post("/v1/jobs", json=job), 413)
    assert answer["errors"][0]["field"] == "data/maps/0/source"


def test_7_webhooks_go_only_to_public_addresses(plain):
    """callback_url at loopback, private, link-local (the metadata service), IPv6 loopback or
    127.0.0.1 written as a number: a 422 naming callback_url, before anything is sent. A name
    that resolves to such an address when the webhook is delivered (here: the job's URL pointed at
    a loopback listener after it was accepted, as DNS rebinding would) is refused on the address
    connected to: the record says "refused", nothing reaches the listener, and nothing says
    whether a port was open."""
    running, client = plain
    for url in ("http://127.0.0.1:6379/", "http://10.0.0.1/hook", "http://169.254.169.254/latest/meta-data",
                "http://[::1]:8000/", "http://2130706433/", "http://localhost:6379/", "http://224.0.0.1/"):
        answer = problem(client.post("/v1/jobs", json={**TRIANGULATION, "callback_url": url}), 422)
        assert answer["errors"][0]["field"] == "callback_url", url
    store = redis.Redis.from_url(running.redis_url, decode_responses=True)
    listener = Listener()
    try:
        job = client.post("/v1/jobs", json={**long_autocalibration(2), "callback_url": "http://hooks.example.invalid/"})
        assert job.status_code == 202, job.text
        job_id = job.json()["id"]
        hook = json.loads(store.hget(f"geocert:job:{job_id}", "webhook"))
        store.hset(f"geocert:job:{job_id}", "webhook",
                   json.dumps({**hook, "url": f"http://127.0.0.1:{listener.port}/hook"}))
        assert ended(client, job_id)["status"] == "succeeded"
        deadline = time.monotonic() + 60
        while (hook := client.get(f"/v1/jobs/{job_id}").json()["webhook"])["state"] != "refused":
            assert time.monotonic() < deadline, f"webhook still {hook['state']}"
            time.sleep(0.2)
        assert hook["attempts"] == 1 and hook["last_error"].startswith("refused:")
        assert str(listener.port) not in hook["last_error"] and "127.0.0.1" not in hook["last_error"]
        time.sleep(1)
        assert listener.connections == 0
    finally:
        listener.close()


def test_7_ipv6_addresses_carrying_a_refused_ipv4_are_refused(plain):
    """IPv6 addresses that a translator or tunnel takes to an IPv4 address: NAT64's well-known
    prefix (a cloud's NAT64 gateway takes 64:ff9b::a00:1 to 10.0.0.1 in its network, and
    64:ff9b::a9fe:a9fe to the metadata address), 6to4, IPv4-translated and IPv4-compatible ones,
    and NAT64's local-use prefix, were accepted as public (Python calls them global): each is
    judged by the IPv4 address inside it. A public IPv4 inside is accepted as before."""
    _, client = plain
    for url in ("http://[64:ff9b::a9fe:a9fe]/", "http://[64:ff9b::a00:1]/", "http://[64:ff9b::7f00:1]:6379/",
                "http://[2002:7f00:1::]/", "http://[::ffff:0:7f00:1]/", "http://[::127.0.0.1]/",
                "http://[64:ff9b:1::a00:1]/"):
        answer = problem(client.post("/v1/jobs", json={**TRIANGULATION, "callback_url": url}), 422)
        assert answer["errors"][0]["field"] == "callback_url", url
    for url in ("http://[64:ff9b::808:808]/", "http://[2002:808:808::1]/"):
        assert client.post("/v1/jobs", json={**TRIANGULATION, "callback_url": url}).status_code == 202, url


def test_4_stereo_segment_matching_keeps_the_time_limit(plain):
    """Segment matching (every pair of segments compared, four assignments solved) never asked
    the clock: 2000 segments an image with time_limit_s 2 held a worker 35 s, 1000 (the default
    limit) 6 s. Now a pair of 1000 random segments an image with a limit of 0.2 s stops within
    its matching: the pair says time_limit and where it stopped."""
    _, client = plain
    job = json.loads((Path(__file__).parents[2] / "examples" / "stereo-lines-pair.json").read_text())
    rng = np.random.default_rng(2)
    for frame in job["data"]["frames"]:
        for side in ("left", "right"):
            frame[side] = np.round(rng.uniform(0, 640, size=(1000, 4)), 2).tolist()
    job["options"] = {"time_limit_s": 0.2}
    response = client.post("/v1/jobs", json=job)
    assert response.status_code == 202, response.text
    finished = ended(client, response.json()["id"])
    pair = finished["result"]["pairs"][0]
    assert pair["reason"].startswith("time_limit: stopped at options.time_limit_s (0.2 s)"), pair["reason"]
    assert "stopped while matching segments" in pair["reason"] and pair["iterations"] == 0


def test_10_an_out_of_range_last_event_id_is_a_422(plain):
    """Stream ids are two 64-bit numbers: ids past them passed the format check and broke the
    stream (an ASGI exception, or a dropped connection)."""
    _, client = plain
    job_id = client.post("/v1/jobs", json=TRIANGULATION).json()["id"]
    ended(client, job_id)
    for value in ("18446744073709551616-0", "0-99999999999999999999", "1-2-3", "x" * 500):
        answer = problem(client.get(f"/v1/jobs/{job_id}/events", headers={"Last-Event-ID": value}), 422)
        assert answer["errors"][0]["field"].lower() == "last-event-id", value
    with client.stream("GET", f"/v1/jobs/{job_id}/events",
                       headers={"Last-Event-ID": "18446744073709551615-18446744073709551615"}) as response:
        assert response.status_code == 200
    assert client.get("/v1/jobs/not:a:job/events").status_code == 404


def test_11_exported_names_are_refused_or_made_safe(plain):
    """A newline in a view's name injected a record into COLMAP's images.txt, and a name such as
    ../../etc/passwd was written verbatim: control characters are refused at submission, and the
    export writes every name as one safe token."""
    from geocert.app.core.security import PUBLIC_OWNER
    from geocert.jobs.store import JobStore

    running, client = plain
    request = {"kind": "reconstruction", "data": {"views": [{"name": "a\n1 1 0 0 0 0 0 0 1 evil.png",
                                                             "image_size": [640, 480]}] * 2,
                                                  "tracks": [{"views": [0, 1], "points": [[1, 2], [3, 4]]}]}}
    answer = problem(client.post("/v1/jobs", json=request), 422)
    assert answer["errors"][0]["field"] == "data/views/0/name" and "control characters" in answer["detail"]
    names = ["../../etc/passwd", "two words.png", "a\nb"]  # the last as stored by an earlier version
    cameras = [{"view": v, "name": name, "registered": True, "image_size": [640, 480],
                "K": [[800, 0, 320], [0, 800, 240], [0, 0, 1]], "R": np.eye(3).tolist(), "t": [0.0, 0.0, float(v)]}
               for v, name in enumerate(names)]
    store = JobStore.from_url(running.redis_url)
    job_id = store.create("reconstruction", request, 1, 1, PUBLIC_OWNER)["id"]
    assert store.mark_running(job_id) and store.claim_end(job_id)
    store.end(job_id, "succeeded", result={"kind": "reconstruction", "cameras": cameras, "points": []})
    response = client.get(f"/v1/jobs/{job_id}/export", params={"format": "colmap"})
    assert response.status_code == 200, response.text
    images = zipfile.ZipFile(io.BytesIO(response.content)).read("images.txt").decode()
    records = [line for line in images.splitlines() if not line.startswith("#")]
    assert len(records) == 2 * len(names)  # two lines an image, nothing injected
    written = [records[2 * k].split(" ")[-1] for k in range(len(names))]
    assert len(written) == len(set(written))
    for name in written:
        assert "/" not in name and "\\" not in name and not name.startswith(".") and name.isprintable()


# ---------------------------------------------------------------------------------------------
# A server with small budgets, webhooks allowed to loopback, short webhook deadlines


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    with cluster(tmp_path_factory.mktemp("small"), workers=1, geocert_max_autocalibration_views="8",
                 geocert_max_view_points_per_job="2000", geocert_max_basis_points_per_job="500",
                 geocert_max_segments_per_frame="40", geocert_max_points_per_map="50",
                 geocert_webhook_allowed_networks="127.0.0.1/32",
                 geocert_webhook_timeout_s="2", geocert_webhook_attempts="2",
                 geocert_webhook_backoff_s="0.2") as (running, client):
        yield running, client


def test_3_more_views_than_the_budget_are_refused_at_submission(small):
    """Direct autocalibration with 300 views ran 205 s past a time limit of 2 s (1000 views: 7.8
    GB): views are a budget figure, refused before the job is queued (the solvers also check the
    clock within a stage's tightening: tests/solvers/autocalibration/test_autocalibration.py)."""
    _, client = small
    data = scenes.make_scene(12, 0.1, seed=5).job_data()
    answer = problem(client.post("/v1/jobs", json={"kind": "autocalibration", "data": data,
                                                   "options": {"method": "direct"}}), 413)
    assert "12 views" in answer["detail"] and "GEOCERT_MAX_AUTOCALIBRATION_VIEWS" in answer["detail"]
    assert answer["errors"][0]["field"] == "data/cameras"
    data = scenes.make_scene(6, 0.1, seed=5).job_data()
    data["points"] = data["points"] * 5  # 6 views of 500 points: 3000 > 2000
    answer = problem(client.post("/v1/jobs", json={"kind": "autocalibration", "data": data}), 413)
    assert "3000 views times points" in answer["detail"] and "GEOCERT_MAX_VIEW_POINTS_PER_JOB" in answer["detail"]


def test_4_stereo_lines_segments_over_the_budget_are_refused(small):
    """2000 segments an image and 100,000 RANSAC iterations held a worker 35 s a pair."""
    _, client = small
    job = json.loads((Path(__file__).parents[2] / "examples" / "stereo-lines-pair.json").read_text())
    frames = job["data"]["frames"]
    frames[1]["right"] = (frames[1]["right"] * 3)[:41]
    answer = problem(client.post("/v1/jobs", json=job), 413)
    assert "41 segments" in answer["detail"] and "GEOCERT_MAX_SEGMENTS_PER_FRAME" in answer["detail"]
    assert answer["errors"][0]["field"] == "data/frames/1/right"


def test_5_a_large_bilinear_basis_is_refused_before_it_is_read(small):
    """300 shapes of 400 points cost 100 s of the API's CPU before queueing (a rank check per
    shape); the basis is a budget figure (and one decomposition now checks it: tests/solvers)."""
    _, client = small
    rng = np.random.default_rng(0)
    basis = np.round(rng.normal(size=(30, 20, 3)), 3).tolist()
    job = {"kind": "bilinear", "data": {"basis": basis, "frames": [{"points": np.round(rng.normal(size=(20, 2)), 3).tolist()}]}}
    answer = problem(client.post("/v1/jobs", json=job), 413)
    assert "600 basis shapes times points" in answer["detail"] and "GEOCERT_MAX_BASIS_POINTS_PER_JOB" in answer["detail"]


def test_6_orient_is_refused_beyond_cameras_times_points(small):
    """/v1/orient builds cameras x points arrays whatever views are given (300 cameras and 200k
    points: +2.1 GB), and the camera count had no limit."""
    _, client = small
    rng = np.random.default_rng(1)
    cameras = [np.round(rng.normal(size=(3, 4)), 3).tolist() for _ in range(10)]
    points = np.round(rng.normal(size=(201, 3)), 3).tolist()
    answer = problem(client.post("/v1/orient", json={"cameras": cameras, "points": points,
                                                      "views": [[0, 1]] * 201}), 413)
    assert "2010 views times points" in answer["detail"] and "GEOCERT_MAX_VIEW_POINTS_PER_JOB" in answer["detail"]
    assert client.post("/v1/orient", json={"cameras": cameras, "points": points[:200]}).status_code == 200


def test_a_map_at_its_points_budget_is_taken(small):
    """GEOCERT_MAX_POINTS_PER_MAP of 50 here: a map of 51 points is refused (413 naming it), one of 50 solved."""
    _, client = small
    rng = np.random.default_rng(5)
    maps = [{"source": np.round(rng.normal(size=(n, 3)), 4).tolist(),
             "target": np.round(rng.uniform(0, 640, size=(n, 2)), 3).tolist()} for n in (50, 51)]
    answer = problem(client.post("/v1/jobs", json={"kind": "resection", "data": {"maps": maps}}), 413)
    assert "51 points in one map" in answer["detail"] and answer["errors"][0]["field"] == "data/maps/1/source"
    response = client.post("/v1/jobs", json={"kind": "resection", "data": {"maps": maps[:1]}})
    assert response.status_code == 202, response.text
    assert ended(client, response.json()["id"])["status"] == "succeeded"


def test_8_a_tarpit_receiver_fails_its_delivery_within_its_deadline_and_holds_no_solver(small):
    """A receiver answering one byte every second: each attempt ends at its 2 s deadline (a
    per-read timeout reset by every byte held the only worker 89 s, and the delivery stayed
    "waiting" for ever); after 2 attempts the record says "failed". Deliveries have their own
    queue and workers: a job submitted meanwhile is solved."""
    _, client = small
    release = threading.Event()

    def dribble(handler):
        handler.wfile.write(b"H")
        handler.wfile.flush()
        while not release.wait(1.0):
            handler.wfile.write(b"T")
            handler.wfile.flush()

    receiver = Receiver(dribble)
    try:
        job_id = first_delivery(client, receiver)
        deadline = time.monotonic() + 60
        other = client.post("/v1/jobs", json=TRIANGULATION).json()["id"]
        assert ended(client, other, limit_s=60)["status"] == "succeeded"
        while (hook := client.get(f"/v1/jobs/{job_id}").json()["webhook"])["state"] != "failed":
            assert time.monotonic() < deadline, f"webhook still {hook['state']} after its attempts"
            time.sleep(0.2)
        assert hook["attempts"] == 2 and hook["last_error"].startswith("failed:")
    finally:
        release.set()
        receiver.close()


def test_9_a_job_deleted_while_its_webhook_is_delivered_leaves_nothing(small):
    """The delivery wrote its record into a job deleted meanwhile: geocert:job:{id} came back
    with the callback URL and no expiry, for ever. Now nothing of the job is written again, and
    every key left of any ended job expires."""
    running, client = small
    store = redis.Redis.from_url(running.redis_url, decode_responses=True)
    deleted, answered = threading.Event(), threading.Event()

    def after_delete(handler):
        deleted.wait(30)
        handler.send_response(200)
        handler.send_header("Content-Length", "0")
        handler.end_headers()
        answered.set()

    receiver = Receiver(after_delete)
    try:
        job_id = first_delivery(client, receiver)
        assert client.delete(f"/v1/jobs/{job_id}").status_code == 204
        deleted.set()
        assert answered.wait(30)
        time.sleep(3)  # the delivery's record written (or not) by now
        assert job_keys(store, job_id) == []
    finally:
        deleted.set()
        receiver.close()
    for key in store.scan_iter("geocert:job:*"):
        meta = store.hget(key, "status") if store.type(key) == "hash" and key.count(":") == 2 else None
        if meta is None or json.loads(meta) in TERMINAL:
            assert store.ttl(key) > 0 or store.type(key) == "none", key
    # Every other key without an expiry is one of the service's own, each kept small by an owner:
    # the workers' heartbeats and slots (entries lapse when a worker stops beating), the running
    # jobs (ended jobs leave it), metrics (one field per label), the signing key, the reaper's
    # lock, and each API key's index, active set and stored bytes (with each job's; ended or
    # expired jobs leave them).
    owned = {"geocert:workers", "geocert:workers:solvers", "geocert:slots", "geocert:slots:owners",
             "geocert:running", "geocert:metrics", "geocert:webhook_secret", "geocert:reaper"}
    for key in store.scan_iter("geocert:*"):
        if not key.startswith("geocert:job:") and store.ttl(key) == -1:
            assert key in owned or (key.startswith("geocert:owner:") and
                                    key.rsplit(":", 1)[1] in ("jobs", "active", "stored", "stored_bytes")), key


def test_9_an_api_keys_index_keeps_no_expired_job(tmp_path):
    """Each API key's index of its jobs (geocert:owner:{key}:jobs, no expiry) dropped an expired
    job only when a listing met it: a key that submits and never lists grew it by one entry a
    job for ever (1,200 a minute at the default rate limit). Now each submission drops the
    oldest entries whose job has expired, so the index holds about the jobs that exist."""
    with cluster(tmp_path, workers=1, geocert_result_ttl_s="1") as (running, client):
        store = redis.Redis.from_url(running.redis_url, decode_responses=True)
        first = [client.post("/v1/jobs", json=TRIANGULATION).json()["id"] for _ in range(5)]
        # A job is given its expiry when it ends, so a 404 means it ended and expired; polling for
        # "done" first could meet the 404 instead (a one-second expiry outruns a poll).
        deadline = time.monotonic() + 60
        while any(client.get(f"/v1/jobs/{job_id}").status_code != 404 for job_id in first):
            assert time.monotonic() < deadline, "the jobs did not expire"
            time.sleep(0.2)
        last = client.post("/v1/jobs", json=TRIANGULATION).json()["id"]
        (index,) = store.scan_iter("geocert:owner:*:jobs")
        assert store.zrange(index, 0, -1) == [last]


def test_a_keys_stored_jobs_are_bounded_in_bytes(tmp_path):
    """Jobs are kept result_ttl_s (7 days) after they end, and nothing bounded what one key kept:
    at the rate limit, some 700 MB an hour of one-track jobs (9.7 KiB each in Redis), 20 GB an
    hour of 5.5 MB ones, for every client's Redis. Now a key's jobs that exist hold at most
    GEOCERT_MAX_STORED_BYTES_PER_KEY, each counted as its request's bytes and at least 16 KiB:
    beyond it a 429 naming it, until the key deletes jobs (or they expire); a large body (its
    items read a batch at a time) is counted by its items' bytes."""
    with cluster(tmp_path, workers=1, geocert_max_stored_bytes_per_key="40000") as (running, client):
        kept = [client.post("/v1/jobs", json=TRIANGULATION) for _ in range(2)]
        assert [response.status_code for response in kept] == [202, 202]
        answer = problem(client.post("/v1/jobs", json=TRIANGULATION), 429)
        assert "GEOCERT_MAX_STORED_BYTES_PER_KEY" in answer["detail"]
        ended(client, kept[0].json()["id"])
        assert client.delete(f"/v1/jobs/{kept[0].json()['id']}").status_code == 204
        assert client.post("/v1/jobs", json=TRIANGULATION).status_code == 202
        ended(client, kept[1].json()["id"])
        assert client.delete(f"/v1/jobs/{kept[1].json()['id']}").status_code == 204
        large = {**TRIANGULATION, "data": {**TRIANGULATION["data"], "tracks": TRIANGULATION["data"]["tracks"] * 30_000}}
        answer = problem(client.post("/v1/jobs", json=large), 429)  # 1.7 MB of items: read a batch at a time
        assert "GEOCERT_MAX_STORED_BYTES_PER_KEY" in answer["detail"]
        store = redis.Redis.from_url(running.redis_url, decode_responses=True)
        assert [key for key in store.scan_iter("geocert:upload:*")] == []


def test_a_keys_stored_results_count_among_its_stored_bytes(tmp_path):
    """A key's stored bytes counted its jobs' requests only, while a job's result is kept as long
    and is several times larger (a track's result some 12 times its request, a quarter of that
    compressed): a key within its limit by its requests kept several times it. Now a job that
    ends adds its stored result (the fragments of a streamed one included) to its key's account,
    so fewer jobs are admitted after it; deleting the job gives every byte back."""
    limit = 6 * 16384
    rng = np.random.default_rng(3)
    tracks = [{"views": [0, 1], "points": [[float(x), float(y)], [float(x) - 80 + float(dx), float(y) + float(dy)]]}
              for x, y, dx, dy in zip(rng.uniform(100, 500, 100), rng.uniform(100, 400, 100),
                                      rng.normal(0, 2, 100), rng.normal(0, 2, 100))]
    many = {**TRIANGULATION, "data": {**TRIANGULATION["data"], "tracks": tracks}}
    with cluster(tmp_path, workers=1, geocert_max_stored_bytes_per_key=str(limit)) as (running, client):
        store = redis.Redis.from_url(running.redis_url)
        response = client.post("/v1/jobs", json=many)
        assert response.status_code == 202, response.text
        job_id = response.json()["id"]
        assert ended(client, job_id)["status"] == "succeeded"
        (account,) = store.scan_iter("geocert:owner:*:stored_bytes")
        request_bytes = len(store.get(f"geocert:job:{job_id}:request")) + sum(
            map(len, store.lrange(f"geocert:job:{job_id}:request:items", 0, -1)))
        result_bytes = store.strlen(f"geocert:job:{job_id}:result") + sum(
            store.hstrlen(f"geocert:job:{job_id}:fragments", start) for start in store.hkeys(f"geocert:job:{job_id}:fragments"))
        assert result_bytes > 16384, result_bytes  # enough to keep out a job more than the request alone
        counted = max(request_bytes, 16384) + result_bytes
        assert int(store.get(account)) == counted
        admitted = 0
        while (answer := client.post("/v1/jobs", json=TRIANGULATION)).status_code == 202:
            admitted += 1
            assert admitted < 10
        assert "GEOCERT_MAX_STORED_BYTES_PER_KEY" in problem(answer, 429)["detail"]
        assert admitted == (limit - counted) // 16384 < (limit - max(request_bytes, 16384)) // 16384
        assert client.delete(f"/v1/jobs/{job_id}").status_code == 204
        assert client.post("/v1/jobs", json=TRIANGULATION).status_code == 202


def test_exports_are_bounded_per_process_and_per_key_and_written_outside_the_api(tmp_path):
    """An export (COLMAP's model, PLY) read, decoded and wrote a whole result in the API process,
    as many at once as were asked: eight COLMAP exports of a 100,000-point result held +5.4 GB
    and kept another key's GET /v1/jobs waiting 17 s. Now each is written in an export process,
    at most GEOCERT_MAX_CONCURRENT_EXPORTS (2) at once per API process and
    GEOCERT_MAX_CONCURRENT_EXPORTS_PER_KEY (1) of one key's, a 429 naming the limit beyond:
    with the export processes stopped (SIGSTOP) while they hold one export of each of two keys,
    a key's second export and a third key's are refused, another request is answered, and the
    two exports end once the processes run again with what they gave before."""
    from geocert.kinds import get_kind

    keys = {"X-API-Key": "one"}, {"X-API-Key": "other"}, {"X-API-Key": "third"}
    with cluster(tmp_path, workers=1, geocert_api_keys="one,other,third") as (running, client):
        jobs = [client.post("/v1/jobs", json=get_kind("reconstruction").example, headers=key).json()["id"]
                for key in keys[:2]]
        for job_id, key in zip(jobs, keys):
            assert ended(client, job_id, headers=key)["status"] == "succeeded"
        paths = [f"/v1/jobs/{job_id}/export?format=ply" for job_id in jobs]
        before = [client.get(path, headers=key) for path, key in zip(paths, keys)]  # starts the export processes
        assert [answer.status_code for answer in before] == [200, 200]
        helpers = spawned(running.api.pid)
        assert helpers, "no export process: the exports were written in the API process"
        for pid in helpers:
            os.kill(pid, signal.SIGSTOP)
        answers: dict[int, httpx.Response] = {}
        senders = [threading.Thread(target=lambda k=k: answers.update({k: client.get(paths[k], headers=keys[k],
                                                                                     timeout=120)}))
                   for k in range(2)]
        nowhere = f"/v1/jobs/{'0' * 32}/export?format=ply"  # a 404 at once when let in: never held

        def refused_while_held(k: int, key) -> dict:
            """Export ``k`` sent and held by the gate, then a request of ``key`` refused. (A request
            sent before the export arrived would be let in, and the export refused, rightly.)"""
            senders[k].start()
            held_by_gate(client, "exports", k + 1)
            answer = client.get(nowhere, headers=key)
            assert answer.headers["Retry-After"]
            return problem(answer, 429)

        try:
            assert "GEOCERT_MAX_CONCURRENT_EXPORTS_PER_KEY" in refused_while_held(0, keys[0])["detail"]
            assert client.get(nowhere, headers=keys[1]).status_code in (404, 422)  # another key's are let in
            detail = refused_while_held(1, keys[2])["detail"]
            assert "GEOCERT_MAX_CONCURRENT_EXPORTS" in detail and "PER_KEY" not in detail
            assert client.get("/v1/jobs", headers=keys[2]).status_code == 200
            assert not answers, "an export was answered while the export processes were stopped"
        finally:
            for pid in helpers:
                os.kill(pid, signal.SIGCONT)
        for sender in senders:
            sender.join(120)
        assert [answers[k].content for k in range(2)] == [answer.content for answer in before]
        assert client.get(paths[1], headers=keys[1]).status_code == 200


# ---------------------------------------------------------------------------------------------
# Worker memory, and a solver process killed under its task


@pytest.fixture(scope="module")
def bounded(tmp_path_factory):
    with cluster(tmp_path_factory.mktemp("bounded"), workers=1, geocert_worker_memory_mb="1200") as (running, client):
        yield running, client


def test_2_a_photo_bomb_fails_its_job_alone_and_is_never_run_again(bounded):
    """Two blank 3000x3000 PNGs, within the pixel budget: feature detection upsamples each to
    6000x6000 and holds about 2 GB. A solver process may hold 1200 MiB here: the allocation
    fails in the task, its job fails with the reason, nothing is queued again (the photo bomb was
    re-queued three times, holding the worker 440 s), and another job is solved after it."""
    running, client = bounded
    store = redis.Redis.from_url(running.redis_url, decode_responses=True)
    response = client.post("/v1/jobs", json=photos(png(3000, 3000), png(3000, 3000)))
    assert response.status_code == 202, response.text
    job = ended(client, response.json()["id"])
    assert job["status"] == "failed"
    assert job["error"]["title"] in ("Memory limit exceeded", "Solver process died"), job["error"]
    assert "GEOCERT_WORKER_MEMORY_MB" in job["error"]["detail"] and "trace" not in job["error"]
    time.sleep(3)
    again = client.get(f"/v1/jobs/{job['id']}").json()
    assert again["status"] == "failed" and again["finished_at"] == job["finished_at"]
    assert store.llen(f"geocert:job:{job['id']}:tasks") == 1 and waiting_tasks(store) == 0
    assert ended(client, client.post("/v1/jobs", json=TRIANGULATION).json()["id"])["status"] == "succeeded"


def test_2_a_solver_process_killed_under_its_task_fails_its_job_and_is_not_run_again(bounded):
    """The kernel's out-of-memory killer takes a solver process (here: SIGKILL to the one running
    the job). Celery used to put its task back on the queue (task_reject_on_worker_lost), where it
    was killed again; now the job fails with the reason and the worker goes on."""
    running, client = bounded
    store = redis.Redis.from_url(running.redis_url, decode_responses=True)
    job_id = client.post("/v1/jobs", json=long_autocalibration(30)).json()["id"]
    deadline = time.monotonic() + 120
    while client.get(f"/v1/jobs/{job_id}").json()["status"] != "running":
        assert time.monotonic() < deadline, "the job did not start"
        time.sleep(0.2)
    main = running.workers[0].pid
    children = open(f"/proc/{main}/task/{main}/children").read().split()
    solvers = [int(c) for c in children if b"webhooks" not in open(f"/proc/{c}/cmdline", "rb").read()]
    assert solvers, children
    for pid in solvers:
        os.kill(pid, signal.SIGKILL)
    job = ended(client, job_id, limit_s=120)
    assert job["status"] == "failed" and job["error"]["title"] == "Solver process died", job["error"]
    time.sleep(15)  # past the visibility timeout and a reaper round: nothing ran it again
    again = client.get(f"/v1/jobs/{job_id}").json()
    assert again["status"] == "failed" and again["finished_at"] == job["finished_at"]
    assert store.hget(f"geocert:job:{job_id}", "reaps") is None and waiting_tasks(store) == 0
    assert ended(client, client.post("/v1/jobs", json=TRIANGULATION).json()["id"])["status"] == "succeeded"


# ---------------------------------------------------------------------------------------------
# Fairness between keys


def test_one_keys_flood_leaves_a_solver_for_another_key(tmp_path):
    """Key A queues four long jobs on a worker of two solver processes; key B's small job is
    solved while A's jobs are still running or queued: A holds one solver at most (every one but
    GEOCERT_SOLVERS_KEPT_FOR_OTHERS), where first come first served gave B the end of the queue."""
    a, b = {"X-API-Key": "key-a"}, {"X-API-Key": "key-b"}
    with cluster(tmp_path, workers=0, geocert_api_keys="key-a,key-b") as (running, client):
        flood = [client.post("/v1/jobs", json=long_autocalibration(20), headers=a).json()["id"] for _ in range(4)]
        running.start_worker(concurrency=2)
        deadline = time.monotonic() + 120
        while all(client.get(f"/v1/jobs/{job_id}", headers=a).json()["status"] == "queued" for job_id in flood):
            assert time.monotonic() < deadline, "the flood did not start"
            time.sleep(0.2)
        small_job = client.post("/v1/jobs", json=TRIANGULATION, headers=b).json()["id"]
        assert ended(client, small_job, headers=b)["status"] == "succeeded"
        statuses = [client.get(f"/v1/jobs/{job_id}", headers=a).json()["status"] for job_id in flood]
        assert statuses.count("running") <= 1 and statuses.count("queued") >= 2, statuses
        for job_id in flood:
            client.post(f"/v1/jobs/{job_id}/cancel", headers=a)


def test_another_keys_job_is_taken_before_a_floods_queued_tasks(tmp_path):
    """Key A's job of five tasks, then key B's job of one: a worker takes A's first task, then
    B's, then A's others (each job's first task is queued ahead of every job's later ones), where
    first in first out had a worker take, and defer for A's share, each of A's tasks before B's."""
    from tests.servers import SHORT_TASKS
    from tests.support import triangulation_job

    a, b = {"X-API-Key": "key-a"}, {"X-API-Key": "key-b"}
    with cluster(tmp_path, workers=0, geocert_api_keys="key-a,key-b", **SHORT_TASKS) as (running, client):
        store = redis.Redis.from_url(running.redis_url, decode_responses=True)
        flood = client.post("/v1/jobs", json=triangulation_job(np.random.default_rng(5), 300, 3, "L2L2"),
                            headers=a).json()["id"]
        other = client.post("/v1/jobs", json=TRIANGULATION, headers=b).json()["id"]
        # The order a worker takes them in: the lists by priority, each from its right end (BRPOP).
        taken = [json.loads(task)["headers"]["argsrepr"] for name in queue_lists("celery")
                 for task in reversed(store.lrange(name, 0, -1))]
        owners = ["A" if flood in args else "B" if other in args else "?" for args in taken]
        assert owners == ["A", "B", "A", "A", "A", "A"], owners
        running.start_worker(concurrency=2)
        assert ended(client, other, headers=b)["status"] == "succeeded"
        assert ended(client, flood, headers=a)["status"] == "succeeded"


def test_one_keys_slow_receivers_leave_webhook_threads_for_another_key(tmp_path):
    """Key A's webhooks go to a receiver that holds every connection; key B's job then ends.
    A webhook worker's 8 threads were all held by A's deliveries, B's waiting behind each of A's
    attempts (40 deliveries to a tarpit: 27 s). Now a key has at most
    GEOCERT_WEBHOOK_DELIVERIES_PER_KEY in flight (the others deferred, not counted as attempts),
    and B's webhook is delivered while A's receiver still holds its connections."""
    a, b = {"X-API-Key": "key-a"}, {"X-API-Key": "key-b"}
    release, lock = threading.Event(), threading.Lock()
    held = {"now": 0, "most": 0}

    def hold(handler):
        with lock:
            held["now"] += 1
            held["most"] = max(held["most"], held["now"])
        release.wait(120)
        with lock:
            held["now"] -= 1
        handler.send_response(200)
        handler.send_header("Content-Length", "0")
        handler.end_headers()

    def answer(handler):
        handler.send_response(200)
        handler.send_header("Content-Length", "0")
        handler.end_headers()

    slow, quick = Receiver(hold), Receiver(answer)
    try:
        with cluster(tmp_path, workers=1, geocert_api_keys="key-a,key-b", geocert_webhook_allowed_networks="127.0.0.1/32",
                     geocert_webhook_timeout_s="150", geocert_webhook_deliveries_per_key="2") as (running, client):
            flood = [client.post("/v1/jobs", json={**TRIANGULATION, "callback_url": slow.url}, headers=a).json()["id"]
                     for _ in range(10)]
            deadline = time.monotonic() + 60
            while slow.received < 2:
                assert time.monotonic() < deadline, "A's deliveries did not start"
                time.sleep(0.1)
            other = client.post("/v1/jobs", json={**TRIANGULATION, "callback_url": quick.url}, headers=b).json()["id"]
            ended(client, other, headers=b)
            deadline = time.monotonic() + 90  # well within A's attempts' 150 s: A's receiver holds them all
            while (hook := client.get(f"/v1/jobs/{other}", headers=b).json()["webhook"])["state"] != "delivered":
                assert time.monotonic() < deadline, f"B's webhook {hook} behind A's held deliveries"
                time.sleep(0.2)
            assert not release.is_set() and 1 <= held["most"] <= 2, held
            states = [client.get(f"/v1/jobs/{job_id}", headers=a).json()["webhook"] for job_id in flood]
            assert all(hook["attempts"] <= 1 and hook["state"] in ("waiting", "retrying") for hook in states), states
            release.set()
    finally:
        release.set()
        slow.close()
        quick.close()


def test_a_solver_process_stopped_with_its_worker_has_its_task_run_again(tmp_path):
    """SIGTERM to a worker's process group (systemd stopping its control group, a deploy) stops
    its solver processes too: unlike a process that died alone, its task is queued again (as a
    task whose whole worker is gone is delivered again), and another worker ends the job."""
    with cluster(tmp_path, workers=1) as (running, client):
        job_id = client.post("/v1/jobs", json=long_autocalibration(3)).json()["id"]
        deadline = time.monotonic() + 120
        while client.get(f"/v1/jobs/{job_id}").json()["status"] != "running":
            assert time.monotonic() < deadline, "the job did not start"
            time.sleep(0.2)
        os.killpg(running.workers[0].pid, signal.SIGTERM)
        running.workers[0].wait(timeout=60)
        running.start_worker()
        job = ended(client, job_id)
        assert job["status"] == "succeeded", job["error"]
