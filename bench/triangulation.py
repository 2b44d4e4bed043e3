"""Triangulation benchmark on the Oxford Dinosaur (4983 tracks, 36 cameras; Oxford VGG data).

Prints, in one run and side by side:
  1. per norm, every track at rel_gap 1e-3 in this process: median / p95 / p99 time and nodes,
     the certified fraction;
  2. on a 200-track sample, SCIP at the same tolerance (per-track wall time, model building
     included, capped at 10 s a track; its box is +-0.05 around the DLT+LM point, a help), and OpenCV DLT followed by Levenberg-Marquardt (how often its point is behind a
     camera, or costs more than the certified optimum);
  3. the whole L2L2 batch through a running service (`geocert serve`, 2 workers), submit to result;
  4. per norm, side by side on every track: the batched solver (fractional.many_tracks.triangulate_many,
     called on chunks of --chunk tracks as the service's kind calls it) against triangulate track by
     track, and (L2L2) OpenCV DLT + LM, CPU time per track;
  (--service-only: the job through the service with each number of workers against the batched
  solve's CPU over the workers, the kind's solve_batch as a worker runs it, documents included;
  and when the job was created, answered, started and finished (its own times) and its result read,
  with the CPU the workers and the API spent meanwhile)
  5. the floor (L2L2): on the Dinosaur and on synthetic scenes of 2 to 20 views, CPU per track of
     the vectorised local solve (fractional.flat: linear start and Levenberg-Marquardt on every
     track at once, uncertified), of per-track scipy (OpenCV DLT, then MINPACK's leastsq), of the
     certified batched solver (triangulate_many: the convexity path, fractional.convexity_path,
     then the search for the tracks it leaves; its certified tracks kept as columns,
     fractional.columns), of the same with a TrackResult made for every track ("+ objects"), of
     the same with every track searched (the convexity path switched off: the solver before it),
     and of the convexity bound alone (the
     vectorised local solve and the bound of fractional.convexity, arrays only), each repeated
     --repeats times, interleaved, with the ratios to the floor.

    .venv/bin/python -m bench.triangulation [--norms L2L2,L2L1,L1L1] [--sample 200] [--no-scip] [--no-service]
                                            [--chunk 500] [--floor-only] [--repeats 3]
    .venv/bin/python -m bench.triangulation --service-only --workers 1,2 [--details full,brief]
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bench import machine_speed_ms
from geocert.solvers.datasets import load_dinosaur
from geocert.core.geometry import norm_cost
from geocert.solvers.fractional.many_tracks import triangulate_many
from geocert.solvers.fractional.triangulation import NORMS, TriangulationOptions, triangulate
from geocert.formulations.fractional import flat as flat_tracks
from geocert.formulations.fractional.convexity import convexity_bounds

# shared/ beside the checkout (or beside the folder of worktrees that holds it).
DINOSAUR = next((folder / "shared" / "data" / "oxford_dinosaur" for folder in Path(__file__).resolve().parents[2:4]
                 if (folder / "shared").is_dir()), Path("shared") / "data" / "oxford_dinosaur")


def load() -> str:
    """The 1, 5 and 15 minute load averages (the machine is shared: other work inflates wall time)."""
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def percentiles(values) -> tuple[float, float, float]:
    values = np.asarray(values, dtype=float)
    return tuple(float(np.percentile(values, q)) for q in (50, 95, 99))


def solve_all(cameras, tracks, norm: str, indices) -> dict:
    options = TriangulationOptions(norm=norm, rel_gap=1e-3)
    times, cpu, nodes, certified, results = [], [], [], 0, {}
    for i in indices:
        track = tracks[i]
        start, start_cpu = time.perf_counter(), time.process_time()
        result = triangulate(cameras[track.views], track.points, options)
        cpu.append(time.process_time() - start_cpu)
        times.append(time.perf_counter() - start)
        nodes.append(result.nodes)
        certified += result.certified
        results[i] = result
    return {"times": times, "cpu": cpu, "nodes": nodes, "certified": certified, "results": results}


def solve_batched(cameras, tracks, norm: str, chunk: int) -> dict:
    """Every track through triangulate_many in chunks of ``chunk`` consecutive tracks: each
    chunk's CPU and wall time shared by its tracks (what a track costs in a batch)."""
    options = TriangulationOptions(norm=norm, rel_gap=1e-3)
    cpu, wall, results = [], [], []
    for start in range(0, len(tracks), chunk):
        part = tracks[start:start + chunk]
        started, started_cpu = time.perf_counter(), time.process_time()
        results += triangulate_many(cameras, [(t.views, t.points) for t in part], options)
        share_cpu, share = (time.process_time() - started_cpu) / len(part), (time.perf_counter() - started) / len(part)
        cpu += [share_cpu] * len(part)
        wall += [share] * len(part)
    return {"cpu": cpu, "wall": wall, "results": results}


def dlt_lm_all(cameras, tracks) -> list[float]:
    """OpenCV DLT + LM's CPU time on every track."""
    from testing.baselines import dlt_lm

    cpu = []
    for track in tracks:
        start = time.process_time()
        dlt_lm(cameras[track.views], track.points)
        cpu.append(time.process_time() - start)
    return cpu


def side_by_side(cameras, tracks, norm: str, ours: dict, chunk: int) -> None:
    batched = solve_batched(cameras, tracks, norm, chunk)
    theirs = [ours["results"][i] for i in range(len(tracks))]
    same = sum((a.status, a.certified) == (b.status, b.certified) for a, b in zip(batched["results"], theirs))
    alone = sum(r.nodes != 1 for r in batched["results"])  # not closed at the root: solved by triangulate
    rows = [("batched", batched["cpu"]), ("per-track", ours["cpu"])]
    if norm == "L2L2":
        rows.append(("DLT + LM", dlt_lm_all(cameras, tracks)))
    print(f"\n{norm} side by side on all {len(tracks)} tracks, CPU ms per track (batched: chunks of {chunk}, each "
          f"chunk's CPU shared by its tracks; {alone} tracks ended off the root path; status and certified as "
          f"triangulate's for {same}/{len(tracks)}; certified {sum(r.certified for r in batched['results'])}):")
    print(f"  {'solver':10} {'median':>8} {'p95':>8} {'p99':>8} {'mean':>8} {'total s':>8}")
    for name, values in rows:
        c = [1e3 * v for v in percentiles(values)]
        print(f"  {name:10} {c[0]:8.3f} {c[1]:8.3f} {c[2]:8.3f} {1e3 * np.mean(values):8.3f} {np.sum(values):8.2f}")
    if norm == "L2L2":
        dlt = np.median(rows[2][1])
        print(f"  ratios of medians to DLT + LM: batched {np.median(batched['cpu']) / dlt:.2f}x, per-track "
              f"{np.median(ours['cpu']) / dlt:.2f}x (target 2x); batched wall total {np.sum(batched['wall']):.2f} s; "
              f"load average {load()}")


def scip_sample(cameras, tracks, norm: str, sample, ours: dict) -> dict:
    from testing.baselines import dlt_lm, scip_triangulate

    times, agree, reached, box_held = [], 0, 0, 0
    for i in sample:
        track = tracks[i]
        cams = cameras[track.views]
        centre = dlt_lm(cams, track.points)[:3]  # an independent centre for SCIP's box
        mine = ours["results"][i]
        box_held += bool(np.max(np.abs(np.array(mine.point[:3]) - centre)) < 0.05)
        start = time.perf_counter()
        X, ok, _ = scip_triangulate(cams, track.points, norm, centre, radius=0.05, time_limit=10, gap=1e-3)
        times.append(time.perf_counter() - start)
        if X is None:
            continue
        reached += ok
        proj = cams @ X
        cost = norm_cost(proj[:, :2] / proj[:, 2:3] - track.points, norm)
        agree += abs(cost - mine.cost) <= 1e-3 * mine.cost + 1e-9
    return {"times": times, "agree": agree, "reached": reached, "box_held": box_held}


def dlt_lm_sample(cameras, tracks, sample, ours: dict) -> dict:
    from testing.baselines import dlt_lm

    behind, worse, below, times, cpu = 0, 0, 0, [], []
    for i in sample:
        track = tracks[i]
        cams = cameras[track.views]
        start, start_cpu = time.perf_counter(), time.process_time()
        X = dlt_lm(cams, track.points)
        cpu.append(time.process_time() - start_cpu)
        times.append(time.perf_counter() - start)
        depth = cams[:, 2] @ X
        proj = cams @ X
        cost = norm_cost(proj[:, :2] / proj[:, 2:3] - track.points, "L2L2")
        optimum = ours["results"][i].cost
        if np.any(depth <= 0):
            behind += 1
            below += cost < optimum * (1 - 1e-6)
        elif cost > optimum * (1 + 1e-6) + 1e-9:
            worse += 1
    return {"behind": behind, "worse": worse, "below_optimum_behind": below, "times": times, "cpu": cpu}


def service_batch(cameras, tracks, workers: int, detail: str = "full") -> dict:
    import httpx

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = os.environ.copy()
    env.pop("GEOCERT_REDIS_URL", None)
    env["GEOCERT_DATA_DIR"] = tempfile.mkdtemp(prefix="geocert-bench-")
    log = open(Path(env["GEOCERT_DATA_DIR"]) / "serve.log", "w")
    server = subprocess.Popen([sys.executable, "-m", "geocert.app.cli", "serve", "--port", str(port), "--workers",
                               str(workers), "--concurrency", "1"], env=env, stdout=log, stderr=log)
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=60) as client:
            deadline = time.monotonic() + 90
            while True:
                try:
                    ready = client.get("/readyz").json()
                    if ready.get("workers", 0) >= workers:
                        break
                except httpx.TransportError:
                    pass
                if time.monotonic() > deadline:
                    raise RuntimeError("service not ready")
                time.sleep(0.3)
            body = {"kind": "triangulation", "options": {"norm": "L2L2", "rel_gap": 1e-3, "detail": detail},
                    "data": {"cameras": cameras.tolist(),
                             "tracks": [{"views": t.views, "points": t.points.tolist()} for t in tracks]}}
            payload = json.dumps(body)
            cpu_before = service_cpu(server.pid)
            began, start = time.time(), time.perf_counter()
            job = client.post("/v1/jobs", content=payload, headers={"content-type": "application/json"}).json()
            posted = time.perf_counter() - start
            with client.stream("GET", f"/v1/jobs/{job['id']}/events", timeout=600) as stream:
                for line in stream.iter_lines():
                    if line == "event: end":
                        break
            final = client.get(f"/v1/jobs/{job['id']}").json()
            wall = time.perf_counter() - start
            cpu_after = service_cpu(server.pid)
        return {"wall": wall, "status": final["status"], "certified": final["result"]["stats"]["certified"],
                "tracks": len(final["result"]["tracks"]), "body_mb": len(payload) / 1e6, "posted": posted,
                "created": final["created_at"] - began, "started": final["started_at"] - began,
                "finished": final["finished_at"] - began,
                "cpu": {part: cpu_after[part] - cpu_before[part] for part in cpu_after}}
    finally:
        server.terminate()
        server.wait(timeout=60)


def service_cpu(pid: int) -> dict[str, float]:
    """CPU seconds so far of `geocert serve`'s processes under ``pid``: its workers (Celery's
    processes, their solver processes among them) and the rest (the API, its helpers, Redis);
    and the seconds the workers' main threads waited in the run queue for a core
    (``workers_wait``, /proc/<pid>/schedstat: on a shared machine, what a second worker cannot
    turn into speed)."""
    found = {"workers": 0.0, "api": 0.0, "workers_wait": 0.0}
    todo = [pid]
    while todo:
        current = todo.pop()
        try:
            with open(f"/proc/{current}/task/{current}/children") as children:
                todo.extend(int(child) for child in children.read().split())
            with open(f"/proc/{current}/cmdline", "rb") as cmdline:
                part = "workers" if b"celery" in cmdline.read() else "api"
            with open(f"/proc/{current}/stat") as stat:
                fields = stat.read().rsplit(")", 1)[1].split()
            found[part] += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
            if part == "workers":
                with open(f"/proc/{current}/schedstat") as schedstat:
                    found["workers_wait"] += int(schedstat.read().split()[1]) / 1e9
        except OSError:
            pass
    return found


def kind_solve_cpu(cameras, tracks, detail: str, repeats: int = 3) -> float:
    """CPU seconds of the triangulation kind's solve_batch on every track, in the chunks a
    worker takes (the kind's chunk_size), documents included: what a job's solve costs, median
    of ``repeats``."""
    from geocert.kinds.triangulation import KIND

    parsed = KIND.parse({"cameras": cameras.tolist(),
                         "tracks": [{"views": t.views, "points": t.points.tolist()} for t in tracks]})
    options = TriangulationOptions(norm="L2L2", rel_gap=1e-3, detail=detail)
    indices = list(range(len(tracks)))
    cpu = []
    for _ in range(repeats):
        start = time.process_time()
        for begin in range(0, len(indices), KIND.chunk_size):
            KIND.solve_batch(parsed, indices[begin:begin + KIND.chunk_size], options, None)
        cpu.append(time.process_time() - start)
    return float(np.median(cpu))


def service_table(cameras, tracks, workers: list[int], details: list[str]) -> None:
    """The service near its solves: each detail's job through `geocert serve` with each number of
    workers, submit to result, against the batched solve's CPU split over the workers (target
    within 1.25x with 2 workers) and from 1 to 2 workers (target at least 1.8x)."""
    for detail in details:
        solve = kind_solve_cpu(cameras, tracks, detail)
        walls = {}
        for count in workers:
            batch = service_batch(cameras, tracks, count, detail)
            walls[count] = batch["wall"]
            print(f"Service, detail {detail}, {count} workers: {batch['tracks']} tracks ({batch['body_mb']:.1f} MB) "
                  f"submit to result {batch['wall']:.2f} s, status {batch['status']}, certified {batch['certified']}; "
                  f"the batched solve's CPU (solve_batch in chunks, documents included) {solve:.3f} s, over "
                  f"{count}: {solve / count:.3f} s; ratio {batch['wall'] / (solve / count):.1f}x (target 1.25x with 2); "
                  f"load average {load()}", flush=True)
            print(f"  when, from the POST's start: the job created {batch['created']:.2f} s, its 202 {batch['posted']:.2f} s, "
                  f"started {batch['started']:.2f} s, finished {batch['finished']:.2f} s, its result read "
                  f"{batch['wall']:.2f} s; CPU meanwhile: the workers "
                  f"{batch['cpu']['workers']:.2f} s ({batch['cpu']['workers'] / solve:.1f}x the solve's, waiting "
                  f"{batch['cpu']['workers_wait']:.2f} s for a core), the API and Redis {batch['cpu']['api']:.2f} s",
                  flush=True)
        if 1 in walls and 2 in walls:
            print(f"Service, detail {detail}: 1 -> 2 workers {walls[1] / walls[2]:.2f}x (target 1.8x)")


def floor_solve(cameras, tracks) -> int:
    """The vectorised local solve (uncertified): how many tracks it ended in front of every camera."""
    flat = flat_tracks.FlatTracks.build(cameras, tracks)
    x, cost = flat_tracks.refine(flat, flat_tracks.linear(flat)[0])
    return int(np.isfinite(cost).sum())


def per_track_scipy(cameras, tracks) -> int:
    from testing.baselines import dlt_leastsq

    for views, points in tracks:
        dlt_leastsq(cameras[views], points)
    return len(tracks)


def batched_certified(cameras, tracks, chunk: int = 500) -> int:
    """The certified solver's results as it returns them (the convexity path's tracks as
    columns, fractional.columns): how many it certified."""
    options = TriangulationOptions(norm="L2L2", rel_gap=1e-3)
    return sum(triangulate_many(cameras, tracks[start:start + chunk], options).certified_count()
               for start in range(0, len(tracks), chunk))


def batched_objects(cameras, tracks, chunk: int = 500) -> int:
    """The same, with every track's TrackResult made (what a caller reading them one by one pays)."""
    options = TriangulationOptions(norm="L2L2", rel_gap=1e-3)
    return sum(r.certified for start in range(0, len(tracks), chunk)
               for r in triangulate_many(cameras, tracks[start:start + chunk], options))


def convexity_bound_only(cameras, tracks) -> int:
    """The vectorised local solve and the convexity bound, arrays only: how many tracks it closes."""
    options = TriangulationOptions(norm="L2L2", rel_gap=1e-3)
    flat = flat_tracks.FlatTracks.build(cameras, tracks)
    x0, ok = flat_tracks.linear(flat)
    x, cost = flat_tracks.refine(flat, x0)
    lower, _, computed = convexity_bounds(flat, x)
    return int((ok & (computed - lower <= np.maximum(options.abs_gap, options.rel_gap * computed))).sum())


def search_only(cameras, tracks, chunk: int = 500) -> int:
    """triangulate_many as it was before the convexity path: every track searched (the path
    switched off for the call)."""
    from unittest import mock

    from geocert.solvers.fractional import many_tracks
    from geocert.formulations.fractional.columns import TrackResults

    with mock.patch.object(many_tracks, "certify_tracks", lambda cameras, tracks, options: TrackResults(len(tracks))):
        return batched_certified(cameras, tracks, chunk)


def synthetic_scenes(views: list[int], points: int) -> list[tuple[str, np.ndarray, list]]:
    from geocert.solvers.reconstruction.synthetic import scene

    out = []
    for n in views:
        s = scene(views=n, points=points, noise_px=0.5, seed=n)
        cameras = np.array([s.K @ np.hstack([R, t[:, None]]) for R, t in zip(s.rotations, s.translations)])
        out.append((f"synthetic {n} views", cameras, [(list(map(int, v)), p) for v, p in s.tracks]))
    return out


def floor_table(datasets, repeats: int) -> None:
    """Section 5: every solver on every dataset, CPU per track, interleaved repeats (the order
    rotates each repeat); the median repeat's figure."""
    solvers = [("floor", floor_solve), ("bound only", convexity_bound_only), ("batched", batched_certified),
               ("+ objects", batched_objects), ("search only", search_only), ("scipy/track", per_track_scipy)]
    print(f"\nThe floor (L2L2, rel_gap 1e-3): CPU microseconds per track, median of {repeats} interleaved "
          f"repeats; ratio = solver / floor (vectorised local solve, uncertified); load average {load()}")
    print(f"  {'dataset':22} {'tracks':>6} " + " ".join(f"{name:>12}" for name, _ in solvers)
          + "  certified (batched / search only)   ratios: bound only, batched, + objects, search only, scipy/track")
    for label, cameras, tracks in datasets:
        cpu = {name: [] for name, _ in solvers}
        counts = {}
        for rep in range(repeats):
            for k in range(len(solvers)):
                name, solve = solvers[(k + rep) % len(solvers)]
                start = time.process_time()
                counts[name] = solve(cameras, tracks)
                cpu[name].append(time.process_time() - start)
        per = {name: 1e6 * float(np.median(v)) / len(tracks) for name, v in cpu.items()}
        print(f"  {label:22} {len(tracks):6d} " + " ".join(f"{per[name]:12.1f}" for name, _ in solvers)
              + f"  {counts['batched']:5d} / {counts['search only']:5d}"
              + f"{'':18} {per['bound only'] / per['floor']:.2f}x, {per['batched'] / per['floor']:.2f}x, "
              f"{per['+ objects'] / per['floor']:.2f}x, "
              f"{per['search only'] / per['floor']:.1f}x, "
              f"{per['scipy/track'] / per['floor']:.1f}x")
    print(f"  load average {load()}")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--norms", default=",".join(NORMS))
    parser.add_argument("--sample", type=int, default=200)
    parser.add_argument("--no-scip", action="store_true")
    parser.add_argument("--no-service", action="store_true")
    parser.add_argument("--workers", default="2", help="comma-separated worker counts, e.g. 1,2 (each a run)")
    parser.add_argument("--chunk", type=int, default=500, help="tracks per triangulate_many call (side by side)")
    parser.add_argument("--details", default="full,brief", help="the service runs' options.detail, each a run")
    parser.add_argument("--floor-only", action="store_true", help="only section 5 (the floor)")
    parser.add_argument("--service-only", action="store_true",
                        help="only the service against the batched solve's CPU (--workers, --details)")
    parser.add_argument("--repeats", type=int, default=3, help="section 5's interleaved repeats")
    parser.add_argument("--synthetic", default="2,3,5,10,20", help="section 5's synthetic scenes' view counts")
    parser.add_argument("--synthetic-points", type=int, default=500)
    args = parser.parse_args()

    cameras, tracks = load_dinosaur(DINOSAUR)
    floor_data = [("Oxford Dinosaur", cameras, [(t.views, t.points) for t in tracks])]
    floor_data += synthetic_scenes([int(n) for n in args.synthetic.split(",")], args.synthetic_points)
    if args.service_only:
        print(f"machine speed (a fixed Python loop) {machine_speed_ms():.0f} ms; load average {load()}")
        service_table(cameras, tracks, [int(w) for w in args.workers.split(",")], args.details.split(","))
        print(f"machine speed at the end {machine_speed_ms():.0f} ms; load average {load()}")
        return
    if args.floor_only:
        print(f"machine speed (a fixed Python loop) {machine_speed_ms():.0f} ms; load average {load()}")
        floor_table(floor_data, args.repeats)
        print(f"machine speed at the end {machine_speed_ms():.0f} ms; load average {load()}")
        return
    everything = range(len(tracks))
    sample = np.random.default_rng(0).choice(len(tracks), size=args.sample, replace=False).tolist()
    print(f"Dinosaur: {len(tracks)} tracks, {len(cameras)} cameras, rel_gap 1e-3, one process; "
          f"machine speed (a fixed Python loop) {machine_speed_ms():.0f} ms; load average {load()}")
    print(f"{'norm':6} {'solver':8} {'tracks':>6} {'median ms':>10} {'p95 ms':>8} {'p99 ms':>8} "
          f"{'nodes med/p95/p99':>18} {'certified':>10}")
    solved = {}
    for norm in args.norms.split(","):
        ours = solve_all(cameras, tracks, norm, everything)
        solved[norm] = ours
        t = [1e3 * v for v in percentiles(ours["times"])]
        c = [1e3 * v for v in percentiles(ours["cpu"])]
        n = percentiles(ours["nodes"])
        print(f"{norm:6} {'geocert':8} {len(tracks):6d} {t[0]:10.2f} {t[1]:8.2f} {t[2]:8.2f} "
              f"{n[0]:6.0f}/{n[1]:.0f}/{n[2]:.0f}".ljust(75) + f"{ours['certified'] / len(tracks):10.2%}"
              f"   CPU ms median/p95/p99 {c[0]:.2f}/{c[1]:.2f}/{c[2]:.2f}")
        if not args.no_scip:
            scip = scip_sample(cameras, tracks, norm, sample, ours)
            s = [1e3 * v for v in percentiles(scip["times"])]
            mine = [1e3 * ours["times"][i] for i in sample]
            print(f"{norm:6} {'SCIP':8} {len(sample):6d} {s[0]:10.2f} {s[1]:8.2f} {s[2]:8.2f} "
                  f"  reached gap {scip['reached']}/{len(sample)}, agrees {scip['agree']}/{len(sample)}, "
                  f"our optimum in its box {scip['box_held']}/{len(sample)}")
            print(f"{'':6} {'ratio':8} {'':6} {s[0] / np.median(mine):9.1f}x  (SCIP median / geocert median "
                  f"on the same {len(sample)} tracks: {np.median(mine):.2f} ms)")
    if "L2L2" in solved:
        base = dlt_lm_sample(cameras, tracks, sample, solved["L2L2"])
        print(f"\nOpenCV DLT + LM on the same {len(sample)} tracks (L2L2): median "
              f"{1e3 * np.median(base['times']):.2f} ms; point behind a camera {base['behind']}, of which "
              f"{base['below_optimum_behind']} cost less than the certified optimum in front; costs more than "
              f"the certified optimum {base['worse']}")
        ours_wall = [1e3 * solved["L2L2"]["times"][i] for i in sample]
        ours_cpu = [1e3 * solved["L2L2"]["cpu"][i] for i in sample]
        print(f"Same {len(sample)} tracks, median wall / CPU ms: geocert L2L2 {np.median(ours_wall):.3f} / "
              f"{np.median(ours_cpu):.3f}, DLT + LM {1e3 * np.median(base['times']):.3f} / "
              f"{1e3 * np.median(base['cpu']):.3f}: ratio {np.median(ours_wall) / (1e3 * np.median(base['times'])):.2f}x "
              f"wall, {np.median(ours_cpu) / (1e3 * np.median(base['cpu'])):.2f}x CPU (target 2x); geocert p99 over all "
              f"tracks {1e3 * np.percentile(solved['L2L2']['times'], 99):.2f} ms wall (target 5 ms); load average {load()}")
        if not args.no_service:
            total = sum(solved["L2L2"]["times"])
            for detail in args.details.split(","):
                walls = {}
                for workers in (int(w) for w in args.workers.split(",")):
                    batch = service_batch(cameras, tracks, workers, detail)
                    walls[workers] = batch["wall"]
                    print(f"\nService, {workers} workers, detail {detail}: {batch['tracks']} tracks "
                          f"({batch['body_mb']:.1f} MB) submit to result {batch['wall']:.2f} s (target 2.5 s with 2), "
                          f"status {batch['status']}, certified {batch['certified']}; in-process single-core solve "
                          f"time track by track {total:.2f} s; load average {load()}")
                if 1 in walls and len(walls) > 1:
                    for workers, wall in walls.items():
                        if workers != 1:
                            print(f"Throughput {workers} workers / 1 worker, detail {detail}: {walls[1] / wall:.2f}x "
                                  "(target 1.8x with 2)")
    for norm, ours in solved.items():
        side_by_side(cameras, tracks, norm, ours, args.chunk)
    floor_table(floor_data, args.repeats)
    print(f"\nMachine speed at the end (the same loop): {machine_speed_ms():.0f} ms; load average {load()}")


if __name__ == "__main__":
    main()
