"""Photos to cameras, geocert against COLMAP, on real photo sets with known cameras (issue 35).

Per set and order of the photos (file order; shuffled with a stated seed; every 2nd photo of a
dense ring), in one run: COLMAP with K unknown (pycolmap's defaults on the CPU: SIFT, exhaustive
matching, incremental mapping, EXIF focal length when present; bench/colmap_baseline.py) and with K
known ("colmap-K"), and geocert through ``geocert solve`` (the CLI's path, the code a user's job
takes) with K unknown and its defaults, with the ring options docs/benchmarks.md gives
(dinoSparseRing), and with K known. Each run is a child process with a time limit. Printed per run:
views registered, rotation error against the ground truth after the best global rotation (median,
max, views above 5 degrees), camera centre error after a similarity alignment (% of the scene's
size), focal length error (%), principal point error (px), cameras certified (of the views
registered) and points certified, what the result claims (``determined``, its warnings, cameras it
flags, whether its poses are determined against their depth-reversed twin and the twin's cost over
theirs), CPU seconds (the child's user + system time, every thread) and wall seconds, and geocert's
CPU over COLMAP's on the same photos, and the same with each side's start-up taken off (a child
that only starts and imports what its runs import, measured at the start: both CPU figures count
it, a service's worker with its modules loaded does not pay it per job). The machine's load is printed with each run: the timings are
only comparable within one run of this bench.

Sets (testing/photo_sets.py says where each comes from, its format, and how a test can use it):
Middlebury multi-view stereo data, dinoSparseRing, templeRing and templeSparseRing (Seitz,
Curless, Diebel, Scharstein and Szeliski, "A comparison and evaluation of multi-view stereo
reconstruction algorithms", CVPR 2006); the Oxford Corridor sequence and its matches (Visual
Geometry Group, University of Oxford); Sceaux Castle (photographs (c) 2012 Pierre Moulon, openMVG's
sample data; K only, so its rotations are compared with COLMAP's, marked "vs COLMAP"); forward
motion down a road, kittiStraight and kittiTurn (every 2nd frame of two 51-frame excerpts of the
KITTI odometry benchmark, Geiger, Lenz and Urtasun, CVPR 2012, CC BY-NC-SA 3.0: K and ground-truth
poses; the copy in github.com/niconielsen32/VisualSLAM, KITTI_sequence_1 and _2). None ships
with geocert; a set whose files are missing is reported with where to get it, or fetched first with
--fetch (bench/fetch_photo_sets.py: every set but dinoSparseRing and the Corridor).

    .venv/bin/pip install -e '.[bench]'       # pycolmap
    .venv/bin/python -m bench.reconstruction_vs_colmap [--data DIR] [--sets dinoSparseRing,templeRing]
        [--orders file,shuffled,every2] [--seed 0] [--runs colmap,colmap-K,geocert,geocert-readme,
        geocert-K,geocert-K-readme; colmap-pinhole on request]
        [--no-colmap | --reuse-colmap] [--timeout 1800] [--json OUT.json] [--verify] [--fetch]

COLMAP's results are stored in DATA/colmap_cache.json (keyed by set, the photos in their order
and a hash of their bytes, pycolmap's version and options): --reuse-colmap takes them from there
where they are and runs COLMAP for the rest; --no-colmap never runs COLMAP (its rows and the CPU
ratios come from the cache when there).
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bench import colmap_baseline, machine_speed_ms
from testing import camera_errors, fetch_photo_sets, photo_sets
from testing.third_party import verify_result

# The ring options for the dinoSparseRing (docs/benchmarks.md, "Photos to tracks, and the K-known path"),
# the only set the docs give options for: bench.reconstruction_images.RING_JOB_OPTIONS, not
# imported from there because that module sets one BLAS thread in this process's environment,
# which COLMAP's child process would inherit.
README_OPTIONS = {"min_inliers": 10, "merge_components": True,
                  "features": {"max_features": 0, "contrast_threshold": 0.005, "ratio": 0.85,
                               "ransac_threshold_px": 2.0, "guided_ratio": 0.8}}
README_SETS = ("dinoSparseRing",)
SETS = ("dinoSparseRing", "templeRing", "templeSparseRing", "corridor", "corridor-matches", "sceaux", "kittiStraight",
        "kittiTurn")
RUNS = ("colmap", "colmap-K", "geocert", "geocert-readme", "geocert-K", "geocert-K-readme")
# Runs on request (--runs): COLMAP with SIMPLE_PINHOLE, no distortion term (what the radial term is worth).
EXTRA_RUNS = ("colmap-pinhole",)


def geocert_job(photo_set, names: list[str], options: dict, matches: bool) -> dict:
    """The reconstruction job a user sends: the photos (base64; PNG and JPEG as published, any
    other format losslessly as PNG), or for the corridor's matches VGG's tracks with the views."""
    import cv2

    if matches:
        index = {n: i for i, n in enumerate(photo_set.names)}
        position = {index[n]: p for p, n in enumerate(names)}
        tracks = []
        for views, points in photo_sets.corridor_tracks(photo_set):
            kept = [(position[int(v)], x) for v, x in zip(views, points) if int(v) in position]
            if len(kept) >= 2:
                tracks.append({"views": [v for v, _ in kept], "points": [list(map(float, x)) for _, x in kept]})
        size = cv2.imread(str(photo_set.path(names[0])), cv2.IMREAD_UNCHANGED).shape
        data = {"tracks": tracks, "views": [{"name": n, "image_size": [size[1], size[0]]} for n in names]}
    else:
        images = []
        for n in names:
            raw = photo_set.path(n).read_bytes()
            if Path(n).suffix.lower() not in (".png", ".jpg", ".jpeg"):
                raw = cv2.imencode(".png", cv2.imread(str(photo_set.path(n)), cv2.IMREAD_UNCHANGED))[1].tobytes()
            images.append({"name": n, "content": base64.b64encode(raw).decode()})
        data = {"images": images}
    return {"kind": "reconstruction", "data": data, "options": options}


def run_geocert(job: dict, timeout_s: float) -> dict:
    """``geocert solve`` on the job in a child process, in the environment the service's workers
    get (one BLAS thread unless the environment says otherwise): the result with wall and CPU
    seconds."""
    from geocert.app.cli import worker_environment

    geocert = Path(sys.executable).with_name("geocert")
    with tempfile.TemporaryDirectory(prefix="geocert-bench-") as work:
        path = Path(work) / "job.json"
        path.write_text(json.dumps(job))
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        try:
            done = subprocess.run([str(geocert), "solve", "--compact", str(path)], capture_output=True, text=True,
                                  timeout=timeout_s, env=worker_environment(dict(os.environ)))
        except subprocess.TimeoutExpired:
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            return {"error": f"time limit {timeout_s:.0f} s", "wall_s": time.perf_counter() - start,
                    "cpu_s": after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime}
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
        if done.returncode != 0:
            return {"error": f"exit {done.returncode}: {(done.stderr or done.stdout).strip()[-500:]}", "wall_s": wall,
                    "cpu_s": cpu}
        return {"result": json.loads(done.stdout), "wall_s": wall, "cpu_s": cpu}


# What each side's child process spends before its first photo: the interpreter and the imports of the
# code a run takes (geocert solve's job path; COLMAP's child: numpy, pycolmap). Both CPU figures count
# it; a service's worker, its modules loaded, does not pay geocert's for each job.
STARTUP_IMPORTS = {"geocert": "import geocert.app.cli, geocert.jobs.runner, geocert.kinds.reconstruction, "
                              "geocert.pipelines.reconstruction.pipeline",
                   "colmap": "import numpy, pycolmap, bench.colmap_baseline"}


def startup_cpu_s(side: str, repeats: int = 3) -> float | None:
    """The median CPU seconds (user + system) of a child process that only starts and imports what
    ``side``'s run imports, in the environment its runs get; None when it cannot import them."""
    from geocert.app.cli import worker_environment

    env = worker_environment(dict(os.environ)) if side == "geocert" else dict(os.environ)
    spent = []
    for _ in range(repeats):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        done = subprocess.run([sys.executable, "-c", STARTUP_IMPORTS[side]], capture_output=True, env=env,
                              cwd=Path(__file__).resolve().parents[1])
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if done.returncode != 0:
            return None
        spent.append(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)
    return float(np.median(spent))


def codes(warnings) -> list[str]:
    """A list of warnings as their codes (a warning is {"code": ..., ...} or a string)."""
    return [w.get("code", str(w)) if isinstance(w, dict) else str(w) for w in warnings or []]


def geocert_figures(result: dict) -> dict:
    """What a geocert result returns and claims: cameras per name, counts, certified fractions,
    ``determined``, warnings (the stages' and the summary's) and cameras it flags."""
    summary = result.get("summary") or {}
    cameras = {c["name"]: (np.array(c["K"]), np.array(c["R"]), np.array(c["t"]))
               for c in result.get("cameras", []) if c.get("registered") and c.get("R") is not None}
    warnings = codes(summary.get("warnings"))
    for stage in result.get("stages", []):
        warnings += codes(stage.get("motion_warnings")) + codes(stage.get("warnings"))
    flagged = sum(1 for c in result.get("cameras", []) if c.get("flags") or c.get("warnings") or c.get("flagged")
                  or c.get("pose_determined") is False)
    reversal = summary.get("depth_reversal") or {}
    certified = sum(1 for c in result.get("cameras", []) if c.get("certified"))
    failed = [f"{stage.get('name')} stage {stage.get('status')}: {stage.get('reason')}"
              for stage in result.get("stages", []) if stage.get("status") in ("failed", "error")]
    reasons = sorted({c.get("reason") for c in result.get("cameras", []) if not c.get("registered") and c.get("reason")})
    # Views the calibration certificate holds that the result does not register: nothing ties them.
    calibration = next((s for s in result.get("stages", []) if s.get("name") == "autocalibration"), {})
    registered_views = {c.get("view") for c in result.get("cameras", []) if c.get("registered")}
    untied = [v for v in calibration.get("certificate_views") or [] if v not in registered_views]
    return {"cameras": cameras, "points": summary.get("points"), "registered": len(cameras), "failed": failed,
            "unregistered_reasons": reasons,
            "cameras_certified": certified / len(cameras) if cameras else None,
            "points_certified": summary.get("points_certified_fraction"),
            "determined": summary.get("autocalibration_determined"), "critical_motion": summary.get("critical_motion"),
            "warnings": sorted(set(warnings)), "flagged": flagged, "rms_px": summary.get("rms_reprojection_px"),
            "poses_determined": summary.get("poses_determined"), "mirror_cost_ratio": reversal.get("cost_ratio"),
            "mirror_statistic": reversal.get("statistic"), "calibration_views_not_registered": len(untied)}


def colmap_figures(run: dict) -> dict:
    cameras = {n: (np.array(c["K"]), np.array(c["R"]), np.array(c["t"])) for n, c in run["cameras"].items()}
    return {"cameras": cameras, "points": run.get("points"), "registered": len(cameras), "models": run.get("models")}


def colmap_run(photo_set, key: str, names, root: Path, run_name: str, args) -> dict | None:
    """COLMAP on the photos, or its cached result (--reuse-colmap, --no-colmap); None when
    --no-colmap and nothing is cached. ``run_name``: "colmap" (K unknown, COLMAP's default camera
    SIMPLE_RADIAL), "colmap-K" (K known) or "colmap-pinhole" (K unknown, SIMPLE_PINHOLE: no
    distortion term, the camera geocert's adjustment has without one)."""
    K = photo_set.K
    known_K = (K[0, 0], K[1, 1], K[0, 2], K[1, 2]) if run_name == "colmap-K" else None
    model = "SIMPLE_PINHOLE" if run_name == "colmap-pinhole" else None
    cache_key = (f"{key}|{colmap_baseline.photos_key(photo_set, names)}|"
                 f"{colmap_baseline.options_key(known_K, model)}")
    if args.reuse_colmap or args.no_colmap:
        if (hit := colmap_baseline.cached(root, cache_key)) is not None:
            return {**hit, "cached": True}
        if args.no_colmap:
            return None
    run = colmap_baseline.run_in_child(photo_set, names, known_K, args.timeout, model)
    run["load"] = os.getloadavg()[0]
    if "error" not in run:
        colmap_baseline.store(root, cache_key, run)
    return run


def reference(photo_set, colmap: dict | None) -> tuple[dict, str]:
    """The cameras to compare against: the ground truth; for a set with K only, COLMAP's
    rotations and centres (when it registered 3 photos or more) with the set's K."""
    if photo_set.truth:
        return photo_set.truth, ""
    if colmap and colmap.get("registered", 0) >= 3:
        return ({n: photo_sets.Camera(photo_set.K, R, t) for n, (_, R, t) in colmap["cameras"].items()}, "vs COLMAP")
    return {n: photo_sets.Camera(photo_set.K, None, None) for n in photo_set.names}, ""


def on_colmaps_views(cameras: dict, colmap: dict | None, truth: dict) -> dict:
    """The median rotation error of the views COLMAP registered too, when it registered fewer
    views (3 or more) than geocert, all of them among geocert's: the accuracy compared on the same
    photos, not on a larger and harder set."""
    if not colmap or "cameras" not in colmap:
        return {}
    shared = set(colmap["cameras"]) & set(cameras)
    if len(shared) < 3 or len(shared) == len(cameras):
        return {}
    errors = camera_errors.compare({n: cameras[n] for n in shared}, truth)
    if "rotation_median_deg" not in errors:
        return {}
    return {"rotation_median_on_colmaps_views_deg": errors["rotation_median_deg"], "colmaps_views": len(shared)}


def fmt(value, spec: str, missing: str = "-") -> str:
    return missing if value is None else format(value, spec)


def row(set_key, order, run_name, total, figures, errors, cpu, wall, colmap_cpu, load, note="",
        startup: dict | None = None) -> str:
    if "error" in figures:
        return (f"| {set_key} | {order} | {run_name} | failed: {figures['error'][:120]} | | | | | | | | | "
                f"{fmt(cpu, '.1f')} | {fmt(wall, '.1f')} | | {load:.1f} |")
    rot = (f"{errors['rotation_median_deg']:.2f} / {errors['rotation_max_deg']:.2f}{' ' + note if note else ''}"
           if "rotation_median_deg" in errors else "-")
    if "rotation_median_on_colmaps_views_deg" in errors:
        rot += (f" ({errors['rotation_median_on_colmaps_views_deg']:.2f} on COLMAP's "
                f"{errors['colmaps_views']})")
    centre = (f"{errors['center_median_pct']:.1f} / {errors['center_max_pct']:.1f}"
              if "center_median_pct" in errors else "-")
    over = str(errors.get("rotation_over_5deg", "-"))
    claims = "-"
    if "warnings" in figures:
        det = {True: "yes", False: "no", None: "-"}[figures["determined"]]
        claims = f"determined {det}; warnings {len(figures['warnings'])}" + (
            f" ({', '.join(figures['warnings'])})" if figures["warnings"] else "") + f"; flags {figures['flagged']}"
        if figures.get("mirror_cost_ratio") is not None:  # the depth-reversed twin's cost over the returned rig's
            poses = {True: "yes", False: "no", None: "-"}[figures.get("poses_determined")]
            claims += f"; poses determined {poses} (twin cost x{figures['mirror_cost_ratio']:.2f})"
        if figures.get("verifies"):  # --verify: the verifier's answer on the result's full certificate
            claims += f"; verifies {figures['verifies']}"
    elif figures.get("models"):
        claims = f"models {figures['models']}"
    ratio = f"{cpu / colmap_cpu:.2f}" if cpu is not None and colmap_cpu and run_name.startswith("geocert") else "-"
    if ratio != "-" and startup and None not in (startup.get("geocert"), startup.get("colmap")):
        ratio += f" ({(cpu - startup['geocert']) / (colmap_cpu - startup['colmap']):.2f} less start-up)"
    return (f"| {set_key} | {order} | {run_name} | {figures['registered']}/{total} | {rot} | {over} | {centre} | "
            f"{fmt(errors.get('focal_error_pct'), '+.1f')} | {fmt(errors.get('principal_point_error_px'), '.1f')} | "
            f"{fmt(figures.get('cameras_certified'), '.2f')} | {fmt(figures.get('points_certified'), '.3f')} | "
            f"{claims} | {fmt(cpu, '.1f')} | {fmt(wall, '.1f')} | {ratio} | {load:.1f} |")


HEADER = ("| set | order | run | registered | rotation error median / max, deg | views > 5 deg | centre error "
          "median / max, % of scene | focal error % | principal point error px | cameras certified | points "
          "certified | claims | CPU s | wall s | CPU / COLMAP's | load |\n" + "|---" * 16 + "|")


def geocert_options(run_name: str, photo_set) -> dict | None:
    """The job's options for a geocert run, None when the run does not apply to the set."""
    options = {}
    if run_name.endswith("readme"):
        if photo_set.key not in README_SETS:
            return None
        options.update(json.loads(json.dumps(README_OPTIONS)))
    if run_name.startswith("geocert-K"):
        options["intrinsics"] = {"K": np.asarray(photo_set.K, dtype=float).tolist()}
    return options


def bench_set(set_key: str, args, root: Path, records: list) -> None:
    matches = set_key == "corridor-matches"
    try:
        photo_set = photo_sets.load("corridor" if matches else set_key, root)
    except photo_sets.MissingSet as missing:
        if not (args.fetch and set_key in fetch_photo_sets.SETS):
            print(f"| {set_key} | | missing: {missing} |" + " |" * 13, flush=True)
            return
        try:
            fetch_photo_sets.fetch(set_key, root)
        except fetch_photo_sets.FetchError as error:
            print(f"| {set_key} | | missing, not fetched: {error} |" + " |" * 13, flush=True)
            return
        photo_set = photo_sets.load(set_key, root)
    orders = [o for o in args.orders if o != "every2" or photo_set.dense_ring]
    for order in orders:
        names = photo_set.order(order, args.seed)
        label = f"{order} (seed {args.seed})" if order == "shuffled" else order
        colmap = {}
        for run_name in args.runs:
            load = os.getloadavg()[0]
            if run_name.startswith("colmap"):
                run = None if matches else colmap_run(photo_set, set_key, names, root, run_name, args)
                if run is None:
                    continue
                figures = {"error": run["error"]} if "error" in run else colmap_figures(run)
                colmap[run_name] = {**figures, "cpu_s": run.get("cpu_s")}
                load = run.get("load", load)
            else:
                options = geocert_options(run_name, photo_set)
                if options is None:
                    continue
                options.update(json.loads(json.dumps(args.options)))
                if args.verify:
                    options["certificate"] = "full"
                run = run_geocert(geocert_job(photo_set, names, options, matches), args.timeout)
                figures = {"error": run["error"]} if "error" in run else geocert_figures(run["result"])
                if args.verify and "result" in run:
                    figures["verifies"] = verify_result(run["result"], args.timeout)
                if args.results and "result" in run:
                    Path(args.results).mkdir(parents=True, exist_ok=True)
                    (Path(args.results) / f"{set_key}-{order}-{run_name}.json").write_text(json.dumps(run["result"]))
            # COLMAP's colmap and colmap-K rows against the ground truth (its K only, for a set without poses)
            truth, note = reference(photo_set, None if run_name in ("colmap", "colmap-K") else colmap.get("colmap"))
            errors = {} if "error" in figures else camera_errors.compare(figures["cameras"], truth)
            if errors and run_name.startswith("geocert") and photo_set.truth:
                errors.update(on_colmaps_views(figures["cameras"], colmap.get("colmap"), truth))
            baseline = colmap.get("colmap-K" if run_name.startswith("geocert-K") and "colmap-K" in colmap else "colmap")
            print(row(set_key, label, run_name + (" (cached)" if run.get("cached") else ""), len(names), figures,
                      errors, run.get("cpu_s"), run.get("wall_s"), (baseline or {}).get("cpu_s"), load, note,
                      args.startup),
                  flush=True)
            for failure in figures.get("failed") or []:
                print(f"|  | | {run_name}: {failure[:300]} |" + " |" * 13, flush=True)
            records.append({"set": set_key, "order": order, "seed": args.seed, "run": run_name, "photos": len(names),
                            "errors": errors, "cpu_s": run.get("cpu_s"), "wall_s": run.get("wall_s"), "load": load,
                            **{k: v for k, v in figures.items() if k != "cameras"}})


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=None, help="data root (default $GEOCERT_BENCH_DATA, else bench-data "
                        "beside the checkout)")
    parser.add_argument("--sets", default=",".join(SETS), help=f"comma-separated, of {', '.join(SETS)}")
    parser.add_argument("--orders", default="file,shuffled,every2", help="file, shuffled, every2 (dense rings only)")
    parser.add_argument("--seed", type=int, default=0, help="the shuffled order's seed (random.Random(seed))")
    parser.add_argument("--runs", default=",".join(RUNS), help=f"comma-separated, of {', '.join(RUNS + EXTRA_RUNS)}")
    parser.add_argument("--no-colmap", action="store_true", help="never run COLMAP: its cached results only")
    parser.add_argument("--reuse-colmap", action="store_true", help="COLMAP's cached results where there are, "
                        "COLMAP run for the others")
    parser.add_argument("--timeout", type=float, default=1800.0, help="seconds per run (each a child process)")
    parser.add_argument("--json", default=None, help="also write every run's figures here")
    parser.add_argument("--options", type=json.loads, default={}, help="JSON object merged into every geocert run's "
                        "options, e.g. '{\"radial_distortion\": \"auto\"}'")
    parser.add_argument("--verify", action="store_true", help="ask geocert for its full certificate and check "
                        "each result with `geocert verify` (a child process), printed in the claims column")
    parser.add_argument("--results", default=None, help="a folder to write each geocert run's result to "
                        "(<set>-<order>-<run>.json), for bench.camera_certification to read")
    parser.add_argument("--fetch", action="store_true", help="fetch a missing set first (bench.fetch_photo_sets: "
                        "the public copy, checked against testing/photo_sets_manifest.json)")
    args = parser.parse_args()
    args.orders, args.runs = args.orders.split(","), args.runs.split(",")
    root = photo_sets.data_root(args.data)
    from geocert.app.cli import worker_environment

    threads = {k: v for k, v in worker_environment(dict(os.environ)).items() if k.endswith("_NUM_THREADS")}
    try:
        version = colmap_baseline.version()
    except ImportError:
        # without pycolmap COLMAP cannot run, but its cached figures are still read (--no-colmap)
        version = "not installed (pip install -e '.[bench]'): COLMAP not run" + (
            ", its cached figures read" if args.no_colmap else "")
        if not args.no_colmap:
            args.runs = [r for r in args.runs if not r.startswith("colmap")]
    print(f"data {root}; pycolmap {version}; {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f} at start, "
          f"machine speed {machine_speed_ms():.0f} ms (bench.machine_speed_ms); "
          f"geocert's BLAS threads (the workers' environment) {threads}; COLMAP every core; shuffled seed {args.seed}")
    args.startup = {side: startup_cpu_s(side) for side in STARTUP_IMPORTS}
    print("start-up CPU s (a child that only imports what a run imports; counted in each run's CPU): "
          + ", ".join(f"{side} {fmt(s, '.2f', 'not measured')}" for side, s in args.startup.items()))
    print(HEADER, flush=True)
    records: list = []
    for set_key in args.sets.split(","):
        bench_set(set_key, args, root, records)
    print(f"load {os.getloadavg()[0]:.1f} at end, machine speed {machine_speed_ms():.0f} ms")
    if args.json:
        Path(args.json).write_text(json.dumps(records, indent=1, default=float))


if __name__ == "__main__":
    main()
