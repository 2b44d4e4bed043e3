"""The job page's load time for a finished job with 5,000 tracks (issue 17's target: within 1 s).

Starts `geocert serve` (embedded Redis, 1 worker, 2 processes), solves a synthetic 5,000-track
triangulation through it (8 cameras around the scene, each track seen by 2 to 4 of them, 0.5 px
noise), then opens `/jobs/{id}` in headless Chromium (Debian's chromium and chromedriver, as the
browser tests use) several times and prints, per load, the time from navigation start to the
finished render (`GC_STATE.rendered`: the result fetched and parsed, the items table built, the
request fetched and every residual reprojected, the histogram and the 3D view drawn). Printed,
not asserted.

    .venv/bin/python -m bench.web [--tracks 5000] [--loads 5]

`--synthetic 100000` instead serves the pages' files beside a stand-in for the API (a finished job
of that many tracks, made up: no solve, no Redis) and prints the render time, then the time to sort
every item by cost and to turn a page, in the browser: the items table's 10^5 case.
"""

from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
import tempfile
import time

import httpx
import numpy as np


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def chrome():
    """Headless Debian chromium through its chromedriver (as the browser tests drive it)."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = "/usr/bin/chromium"
    for argument in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--window-size=1280,1000"):
        options.add_argument(argument)
    return webdriver.Chrome(options=options, service=Service("/usr/bin/chromedriver"))


def open_rendered(driver, url: str, timeout: float, poll: float) -> float:
    """Opens ``url`` afresh and waits for the page's finished render; its ms after navigation start."""
    driver.get("about:blank")
    driver.get(url)
    deadline = time.monotonic() + timeout
    while (rendered := driver.execute_script("return window.GC_STATE && window.GC_STATE.rendered")) is None:
        assert time.monotonic() < deadline, "the page did not render"
        time.sleep(poll)
    return rendered


def scene_job(tracks: int, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
    cameras = []
    for angle in np.linspace(0, np.pi / 2, 8):  # a quarter circle at distance 6, looking at the origin
        centre = 6 * np.array([np.sin(angle), 0.3 * np.cos(3 * angle), -np.cos(angle)])
        forward = -centre / np.linalg.norm(centre)
        right = np.cross([0, 1, 0], forward)
        right /= np.linalg.norm(right)
        R = np.array([right, np.cross(forward, right), forward])
        cameras.append(K @ np.hstack([R, (-R @ centre)[:, None]]))
    body = []
    for _ in range(tracks):
        X = np.append(rng.uniform(-1, 1, 3), 1.0)
        views = sorted(rng.choice(8, size=int(rng.integers(2, 5)), replace=False).tolist())
        points = []
        for v in views:
            x = cameras[v] @ X
            points.append((x[:2] / x[2] + rng.normal(0, 0.5, 2)).tolist())
        body.append({"views": views, "points": points})
    return {"kind": "triangulation", "data": {"cameras": [c.tolist() for c in cameras], "tracks": body},
            "options": {"norm": "L2L2", "rel_gap": 1e-3}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tracks", type=int, default=5000)
    parser.add_argument("--loads", type=int, default=5)
    parser.add_argument("--base", help="a running service's URL (with --job): load that job's page, start nothing")
    parser.add_argument("--job", help="the id of a finished job at --base")
    parser.add_argument("--synthetic", type=int, help="items of a made-up finished job served by a stand-in API")
    args = parser.parse_args()
    if args.synthetic:
        synthetic(args.synthetic, args.loads)
        return
    if args.base and args.job:
        print(f"job {args.job} at {args.base}")
        load_pages(args.base, args.job, args.loads, args.tracks)
        return

    port = free_port()
    env = {key: value for key, value in os.environ.items() if key != "GEOCERT_REDIS_URL"}
    env["GEOCERT_DATA_DIR"] = tempfile.mkdtemp(prefix="geocert-bench-web-")
    process = subprocess.Popen([sys.executable, "-m", "geocert.app.cli", "serve", "--port", str(port),
                                "--workers", "1", "--concurrency", "2"], env=env,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    base = f"http://127.0.0.1:{port}"
    try:
        with httpx.Client(base_url=base, timeout=60) as client:
            deadline = time.monotonic() + 90
            while True:
                try:
                    if client.get("/readyz").status_code == 200:
                        break
                except httpx.TransportError:
                    pass
                assert process.poll() is None and time.monotonic() < deadline, "service not ready"
                time.sleep(0.3)
            start = time.monotonic()
            job_id = client.post("/v1/jobs", json=scene_job(args.tracks)).json()["id"]
            while (job := client.get(f"/v1/jobs/{job_id}").json())["status"] not in ("succeeded", "failed", "cancelled"):
                time.sleep(0.5)
            size = len(client.get(f"/v1/jobs/{job_id}").content)
            print(f"{args.tracks} tracks solved in {time.monotonic() - start:.1f} s ({job['status']}, "
                  f"{job['result']['stats']['certified']} certified); job document {size / 1e6:.1f} MB")
        load_pages(base, job_id, args.loads, args.tracks)
    finally:
        process.terminate()
        process.wait(timeout=30)


def load_pages(base: str, job_id: str, loads: int, tracks: int) -> None:
    with httpx.Client(base_url=base, timeout=60) as client:
        start = time.perf_counter()
        client.get(f"/v1/jobs/{job_id}").raise_for_status()
        print(f"GET /v1/jobs/{{id}} alone: {1000 * (time.perf_counter() - start):.0f} ms")
    driver = None
    try:
        driver = chrome()
        times = []
        for load in range(loads):
            rendered = open_rendered(driver, f"{base}/jobs/{job_id}", 60, 0.02)
            view = driver.execute_script("return window.GC_STATE.view")
            marks = driver.execute_script("return window.GC_STATE.timings")
            times.append(rendered)
            print(f"load {load + 1}: rendered {rendered:.0f} ms after navigation start "
                  f"({view['points']} points, {view['cameras']} cameras in the 3D view); "
                  f"ms at: {', '.join(f'{name} {at}' for name, at in marks.items())}")
        print(f"page load of a finished {tracks}-track job: median {np.median(times):.0f} ms, "
              f"max {max(times):.0f} ms over {len(times)} loads (target: 1000 ms)")
    finally:
        if driver is not None:
            driver.quit()


def synthetic(tracks: int, loads: int) -> None:
    """The job page against a stand-in API serving a made-up finished job of ``tracks`` tracks."""
    import json
    import threading
    from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
    from pathlib import Path

    web = Path(__file__).resolve().parents[1] / "geocert" / "app" / "web"
    job = scene_job(tracks)
    rng = np.random.default_rng(1)
    items = []
    for index in range(tracks):
        cost = float(rng.gamma(2.0, 0.5))
        items.append({"point": rng.uniform(-1, 1, 3).tolist(), "at_infinity": False, "cost": cost,
                      "lower_bound": cost * 0.9995, "gap": cost * 5e-4, "status": "optimal", "certified": True,
                      "nodes": int(rng.integers(1, 40)), "elapsed_s": float(rng.uniform(0.005, 0.05)), "reason": None,
                      "certificate": {"scope": "every point in front of every camera", "tolerance": cost * 1e-3,
                                      "tolerance_met": True, "leaves": 3,
                                      "root_region": {"reference_view": 0, "functionals": rng.normal(size=(2, 4)).tolist(),
                                                      "lower": [0.1, 0.2], "upper": [0.3, 0.4]}}})
    document = json.dumps({
        "id": "0" * 32, "kind": "triangulation", "status": "succeeded", "created_at": time.time() - 60,
        "started_at": time.time() - 59, "finished_at": time.time(),
        "progress": {"nodes": 1, "open_boxes": 0, "lower_bound": 1.0, "upper_bound": 1.0, "gap_abs": 0.0, "gap_rel": 0.0,
                     "items_done": tracks, "items_total": tracks, "items_certified": tracks, "elapsed_s": 59.0},
        "links": {}, "error": None, "webhook": None,
        "result": {"kind": "triangulation", "norm": "L2L2", "tracks": items, "certificate": None,
                   "stats": {"items": tracks, "certified": tracks, "nodes": tracks, "solve_s": 1.0, "elapsed_s": 59.0,
                             "statuses": {"optimal": tracks}}}}).encode()
    request = json.dumps(job).encode()
    problems = json.dumps([{"kind": "triangulation", "description": "", "item_name": "tracks",
                            "request_schema": {}, "default_options": {}}]).encode()
    end = b'event: end\ndata: {"status": "succeeded", "error": null}\n\n'
    types = {".js": "text/javascript", ".css": "text/css", ".html": "text/html", ".svg": "image/svg+xml"}

    class StandIn(BaseHTTPRequestHandler):
        def log_message(self, *args):
            pass

        def do_GET(self):
            path = self.path.split("?")[0]
            if path.startswith("/jobs/"):
                body, kind = (web / "job.html").read_bytes(), "text/html"
            elif path == "/web/config.json":
                body, kind = b'{"keys_required": false}', "application/json"
            elif path.startswith("/web/"):
                file = web / path[len("/web/"):]
                body, kind = file.read_bytes(), types.get(file.suffix, "application/octet-stream")
            elif path == "/v1/problems":
                body, kind = problems, "application/json"
            elif path.endswith("/request"):
                body, kind = request, "application/json"
            elif path.endswith("/events"):
                body, kind = end, "text/event-stream"
            elif path.startswith("/v1/jobs/"):
                body, kind = document, "application/json"
            else:
                self.send_error(404)
                return
            self.send_response(200)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

    server = ThreadingHTTPServer(("127.0.0.1", free_port()), StandIn)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    base = f"http://127.0.0.1:{server.server_address[1]}"
    print(f"a made-up finished job of {tracks} tracks: job document {len(document) / 1e6:.1f} MB, "
          f"request {len(request) / 1e6:.1f} MB")
    driver = chrome()
    try:
        for load in range(loads):
            rendered = open_rendered(driver, f"{base}/jobs/{'0' * 32}", 120, 0.05)
            timed = driver.execute_script("""
                const t = (f) => { const s = performance.now(); f(); return Math.round(performance.now() - s); };
                const sort = document.querySelector("#items thead button[data-sort='cost']");
                return {sort: t(() => sort.click()), sort_back: t(() => sort.click()),
                        next: t(() => document.getElementById('next').click()),
                        last: t(() => document.getElementById('last').click()),
                        note: document.getElementById('page-note').textContent};""")
            print(f"load {load + 1}: rendered {rendered:.0f} ms; sorting {tracks} items by cost {timed['sort']} ms "
                  f"(and back {timed['sort_back']} ms), next page {timed['next']} ms, last page {timed['last']} ms "
                  f"({timed['note']}); ms at: {driver.execute_script('return window.GC_STATE.timings')}")
    finally:
        driver.quit()
        server.shutdown()


if __name__ == "__main__":
    main()
