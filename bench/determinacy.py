"""Determinacy (issues 19, 37): the intervals' widths against the true errors over synthetic scenes
and real camera sets, how often the truth lies inside (coverage), and how often it does among the
intervals narrow enough to fix their quantity (`determined`'s promise), per kind; and how often
degenerate scenes (and real critical layouts) are flagged.

    .venv/bin/python -m bench.determinacy [--scenes 40] [--autocalibration-scenes 10] [--no-real]
    .venv/bin/python -m bench.determinacy --triangulation-only   # the real camera sets' tracks only
    .venv/bin/python -m bench.determinacy --resection-only       # the real camera sets' resections only
    .venv/bin/python -m bench.determinacy --resection-l1         # their L1 resections' proven intervals only
    .venv/bin/python -m bench.determinacy --resection-l1-synthetic  # L1 resections' proven centres, 20 cameras
    .venv/bin/python -m bench.determinacy --autocalibration-proven  # the metric stage's proven intervals
    .venv/bin/python -m bench.determinacy --direct-views-proven 6 --autocalibration-scenes 6  # each view's, direct
    .venv/bin/python -m bench.determinacy --direct-views-proven-real  # the same on the Model House's cameras
    .venv/bin/python -m bench.determinacy --direct-intrinsics-proven-real  # one K's proven intrinsics, Model House
    .venv/bin/python -m bench.determinacy --lone-tracks      # jobs of one 2-view track (Dinosaur), against pooled
    .venv/bin/python -m bench.determinacy --critical-real    # hemisphere elevation-band rings, KITTI windows

Real sets: under $GEOCERT_BENCH_DATA (default bench-data beside the checkout) and $GEOCERT_SHARED_DATA (default
/work/shared/data); those absent are left out.

The intervals are 3 standard errors from the local curvature (docs/kinds.md, "Determinacy"): for a
linear fit with Gaussian noise each covers its quantity 99.7% of the time.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import time
from pathlib import Path
from unittest import mock

import numpy as np

from geocert.jobs.runner import solve_job
from geocert.solvers.autocalibration import scenes
from geocert.core.determinacy import fixes
from testing.determinacy import cameras_looking_at_origin, project

SHARED_DATA = Path(os.environ.get("GEOCERT_SHARED_DATA", "/work/shared/data"))
BENCH_DATA = Path(os.environ.get("GEOCERT_BENCH_DATA") or Path(__file__).resolve().parents[2] / "bench-data")


def tally(rows: dict, name: str, interval: dict, truth: float) -> None:
    row = rows.setdefault(name, {"inside": 0, "n": 0, "widths": [], "errors": [], "unbounded": 0, "fixing": 0,
                                 "fixing_inside": 0})
    row["n"] += 1
    if interval["lower"] is None:
        row["unbounded"] += 1
        return
    inside = interval["lower"] <= truth <= interval["upper"]
    row["inside"] += inside
    if fixes(interval):  # narrow enough for `determined`: what a user may rely on
        row["fixing"] += 1
        row["fixing_inside"] += inside
    row["widths"].append(interval["upper"] - interval["lower"])
    row["errors"].append(abs(interval["value"] - truth))


def triangulation(n: int, rng) -> tuple[dict, int, int]:
    rows, flagged, narrow_flagged = {}, 0, 0
    for _ in range(n):
        views = int(rng.integers(2, 8))
        angles = rng.uniform(0, np.pi / 2, views)
        centres = 10 * np.c_[np.sin(angles), rng.uniform(-0.3, 0.3, views), np.cos(angles)]
        cameras = cameras_looking_at_origin(centres)
        X = rng.uniform(-1, 1, 3)
        points = project(cameras, X) + rng.normal(scale=1.0, size=(views, 2))
        item = solve_job({"kind": "triangulation", "data": {"cameras": cameras.tolist(), "tracks": [
            {"views": list(range(views)), "points": points.tolist()}]}, "options": {}})["tracks"][0]
        d = item["determinacy"]
        flagged += bool(d["warnings"])
        for k, name in enumerate("xyz"):
            tally(rows, name, next(i for i in d["intervals"] if i["name"] == name), X[k])
        narrow = np.c_[rng.uniform(-0.05, 0.05, views), np.zeros(views), np.full(views, 10.0)]
        cameras = cameras_looking_at_origin(narrow)
        points = project(cameras, X) + rng.normal(scale=1.0, size=(views, 2))
        item = solve_job({"kind": "triangulation", "data": {"cameras": cameras.tolist(), "tracks": [
            {"views": list(range(views)), "points": points.tolist()}]}, "options": {}})["tracks"][0]
        narrow_flagged += item["determinacy"] is not None and "near_zero_parallax" in [
            w["code"] for w in item["determinacy"]["warnings"]]
    return rows, flagged, narrow_flagged


def resection(n: int, rng) -> tuple[dict, int, int]:
    rows, flagged, coplanar_flagged = {}, 0, 0
    for _ in range(n):
        centre = np.array([*rng.uniform(-2, 2, 2), -10.0])
        camera = cameras_looking_at_origin(centre[None, :])
        for coplanar in (False, True):
            points3 = rng.uniform(-2, 2, size=(int(rng.integers(8, 30)), 3))
            if coplanar:
                points3[:, 2] = 0.2 * points3[:, 0] + rng.normal(scale=0.005, size=len(points3))
            image = np.array([project(camera, X)[0] for X in points3]) + rng.normal(scale=0.5, size=(len(points3), 2))
            item = solve_job({"kind": "resection", "data": {"maps": [
                {"source": points3.tolist(), "target": image.tolist()}]}, "options": {}})["maps"][0]
            d = item["determinacy"]
            if d is None:
                continue
            codes = [w["code"] for w in d["warnings"]]
            if coplanar:
                coplanar_flagged += "near_coplanar_points" in codes
                continue
            flagged += bool(codes)
            for k, name in enumerate(("centre_x", "centre_y", "centre_z")):
                tally(rows, name, next(i for i in d["intervals"] if i["name"] == name), centre[k])
                if d["proven_intervals"] is not None:  # proven: the estimate's value and tolerance beside it
                    estimate = next(i for i in d["intervals"] if i["name"] == name)
                    tally(rows, f"proven {name}", {**d["proven_intervals"]["intervals"][k],
                                                   "value": estimate["value"], "tolerance": estimate["tolerance"]},
                          centre[k])
    return rows, flagged, coplanar_flagged


def autocalibration(n: int, rng) -> tuple[dict, int, int]:
    rows, flagged, ring_flagged = {}, 0, 0
    truth = {"focal_x": 1000.0, "focal_y": 1000.0, "skew": 0.0, "principal_u": 500.0, "principal_v": 500.0}
    for trial in range(n):
        views = (10, 20)[trial % 2]
        for motion in ("sphere", "ring"):
            scene = scenes.make_scene(views, 0.5, seed=900 + trial, motion=motion)
            result = solve_job({"kind": "autocalibration", "data": scene.job_data(),
                                "options": {"time_limit_s": 10}})
            d = result["stages"][1].get("determinacy")
            if d is None:
                continue
            codes = [w["code"] for w in d["warnings"]]
            if motion == "ring":
                ring_flagged += "orbital_motion" in codes or "rotation_about_one_axis" in codes
                continue
            flagged += bool(codes)
            for name, value in truth.items():
                tally(rows, name, next(i for i in d["intervals"] if i["name"] == name), value)
    return rows, flagged, ring_flagged


def temple_ring_cameras() -> Path:
    """templeRing's cameras' folder, else its photo set's (which holds the same templeR_par.txt)."""
    folder = BENCH_DATA / "middlebury_templeRing_cameras"
    return folder if folder.exists() else BENCH_DATA / "middlebury_templeRing"


def real_camera_sets() -> list[tuple[str, object, bool, dict]]:
    """(name, views, critical, intrinsics ranges) of the real camera sets present: the
    Middlebury dino's hemisphere (random 20 of its 363 views; a general motion, f = 3310 px beyond
    the default ranges), templeRing (20 of its 47 ring views, the issue's example, and its first
    20), templeSparseRing (16 views of the same ring, fetched with its photos), dinoSparseRing, the
    Oxford Model House and Corridor (critical or near-critical)."""
    from geocert.solvers import datasets

    found = []
    hemisphere = BENCH_DATA / "middlebury_dino_cameras"
    if hemisphere.exists():
        views = datasets.load_middlebury(hemisphere)
        for seed in range(2, 8):
            found.append((f"dino hemisphere, 20 views (seed {seed})",
                          views.subset(np.random.default_rng(seed).choice(363, 20, replace=False)), False,
                          {"focal": [1000.0, 6000.0]}))
    temple = temple_ring_cameras()
    if temple.exists():
        views = datasets.load_middlebury(temple)
        for seed in (1, 2, 3):
            found.append((f"templeRing, 20 views (seed {seed})",
                          views.subset(np.random.default_rng(seed).choice(47, 20, replace=False)), True, {}))
        found.append(("templeRing, first 20 views", views.subset(range(20)), True, {}))
    if (BENCH_DATA / "middlebury_templeSparseRing").exists():  # bench.fetch_photo_sets fetches it
        found.append(("templeSparseRing, 16 views", datasets.load_middlebury(BENCH_DATA / "middlebury_templeSparseRing"),
                      True, {}))
    if (SHARED_DATA / "middlebury_dinoSparseRing").exists():
        found.append(("dinoSparseRing, 14 views", datasets.load_middlebury(SHARED_DATA / "middlebury_dinoSparseRing"),
                      True, {"focal": [1000.0, 6000.0]}))
    if (SHARED_DATA / "oxford_house").exists():
        found.append(("Oxford Model House, 10 views", datasets.load_vgg_cameras(SHARED_DATA / "oxford_house", "house",
                                                                                (768, 576)), True, {}))
    if (BENCH_DATA / "oxford_corridor").exists():
        found.append(("Oxford Corridor, 11 views", datasets.load_vgg_cameras(BENCH_DATA / "oxford_corridor", "bt",
                                                                             (512, 512)), True, {}))
    return found


def real_autocalibration(noise_px: float = 0.5) -> tuple[dict, list[str]]:
    """Each real set's ground-truth cameras moved to a random projective frame with noise_px of
    noise (scenes.from_cameras), autocalibrated with the defaults (ranges widened where the truth
    lies beyond them): the metric stage's intervals against the set's first K."""
    rows, lines = {}, []
    for name, views, critical, intrinsics in real_camera_sets():
        scene = scenes.from_cameras(views.cameras, views.box, noise_px, seed=0, image_size=views.image_size)
        result = solve_job({"kind": "autocalibration", "data": scene.job_data(),
                            "options": {"time_limit_s": 10, **({"intrinsics": intrinsics} if intrinsics else {})}})
        K = views.K[0]
        truth = {"focal_x": K[0, 0], "focal_y": K[1, 1], "skew": K[0, 1], "principal_u": K[0, 2],
                 "principal_v": K[1, 2]}
        d = result["stages"][1].get("determinacy")
        found = None if result["K"] is None else result["K"][0][0]
        if d is None:
            lines.append(f"  {name}: no metric answer")
            continue
        codes = [w["code"] for w in d["warnings"]]
        missed = [i["name"] for i in d["intervals"] if fixes(i) and not i["lower"] <= truth[i["name"]] <= i["upper"]]
        lines.append(f"  {name}: f {found:.0f} px (truth {K[0, 0]:.0f}), {'critical' if critical else 'general'}; "
                     f"warnings {codes or 'none'}; determined {d['determined']}; intervals fixing their quantity "
                     f"but missing the truth: {missed or 'none'}")
        if not critical:
            for key, value in truth.items():
                tally(rows, key, next(i for i in d["intervals"] if i["name"] == key), value)
    return rows, lines


def real_track_scenes(rng, noise_px: float, count: int) -> list[tuple[str, np.ndarray, list, np.ndarray]]:
    """(name, cameras, tracks, true points) on real camera sets: the Dinosaur's 36 cameras with its
    own tracks (their certified points taken as the truth), the Model House's cameras with its 3D
    points and which views see them, dinoSparseRing's, templeRing's and templeSparseRing's cameras
    with points drawn in the box they state, each seen by 2 to 6 consecutive views of the ring;
    every observation the truth's projection plus noise_px of noise; and the Model House's own
    measured corners against its published 3D points (a reconstruction, not a survey). Up to
    ``count`` tracks a set."""
    from geocert.solvers import datasets

    found, observed = [], []
    if (SHARED_DATA / "oxford_dinosaur").exists():
        cameras, tracks = datasets.load_dinosaur(SHARED_DATA / "oxford_dinosaur")
        chosen = rng.choice(len(tracks), min(count, len(tracks)), replace=False)
        first = solve_job({"kind": "triangulation", "data": {"cameras": cameras.tolist(), "tracks": [
            {"views": tracks[i].views, "points": tracks[i].points.tolist()} for i in chosen]},
            "options": {"detail": "brief"}})["tracks"]
        kept = [(tracks[i].views, t["point"]) for i, t in zip(chosen, first) if t["certified"] and not t["at_infinity"]]
        found.append(("Dinosaur, 36 views, its own tracks", cameras, [v for v, _ in kept],
                      np.array([X for _, X in kept])))
    if (SHARED_DATA / "oxford_house").exists():
        cameras, points, views = datasets.load_house(SHARED_DATA / "oxford_house")
        seen: dict[int, list[int]] = {}
        for v, correspondences in enumerate(views):
            for i in correspondences.point_indices:
                seen.setdefault(int(i), []).append(v)
        chosen = [i for i in sorted(seen) if len(seen[i]) >= 2][:count]
        found.append(("Oxford Model House, 10 views, its 3D points", cameras, [seen[i] for i in chosen],
                      points[chosen]))
        corners = {(v, int(i)): pixel for v, c in enumerate(views) for i, pixel in zip(c.point_indices, c.pixels)}
        observed.append(("Model House, its measured corners (3D: its own)", cameras, [
            {"views": seen[i], "points": [corners[(v, i)].tolist() for v in seen[i]]} for i in chosen],
            points[chosen]))
    rings = [("dinoSparseRing, 16 views", SHARED_DATA / "middlebury_dinoSparseRing"),
             ("templeRing, 47 views", temple_ring_cameras()),
             ("templeSparseRing, 16 views", BENCH_DATA / "middlebury_templeSparseRing")]
    for name, directory in rings:
        if not directory.exists():
            continue
        ring = datasets.load_middlebury(directory)
        lower, upper = ring.box
        X = rng.uniform(lower, upper, size=(count, 3))
        m = len(ring.names)
        starts, lengths = rng.integers(0, m, count), rng.integers(2, 7, count)
        found.append((name, ring.cameras, [sorted(((s + np.arange(k)) % m).tolist()) for s, k in zip(starts, lengths)],
                      X))
    scenes_out = []
    for name, cameras, views, X in found:
        tracks = [{"views": list(map(int, v)), "points": (project(cameras[list(v)], x)
                                                          + rng.normal(scale=noise_px, size=(len(v), 2))).tolist()}
                  for v, x in zip(views, X)]
        scenes_out.append((name, cameras, tracks, X))
    return scenes_out + observed


def real_triangulation(rng, noise_px: float = 0.5, count: int = 1000) -> list[str]:
    """Coverage of the truth on real camera layouts: the estimated intervals (x, y, z, each and
    all three) and the proven ones (the box every point within cost_increase of the optimum lies
    in), with the proven box's width over the estimate's. The truth lies in the set when its
    cost exceeds the optimum's by at most cost_increase (3^2 times the fit's own residual
    variance, a noisy estimate on a track of few views), so the proven box's coverage of the
    truth is that of the set, not a certainty; what is certain is that it holds the set."""
    lines = [f"  {'scene':>44} | tracks | est. x/y/z coverage | est. all 3 | proven | proven all 3 | "
             "proven / est. width (median, z)"]
    for name, cameras, tracks, X in real_track_scenes(rng, noise_px, count):
        items = solve_job({"kind": "triangulation", "data": {"cameras": cameras.tolist(), "tracks": tracks},
                           "options": {}})["tracks"]
        inside, proven_inside, proven, ratios = np.zeros((len(items), 3), bool), [], 0, []
        for t, (item, x) in enumerate(zip(items, X)):
            d = item["determinacy"]
            if d is None:
                continue
            est = [next(i for i in d["intervals"] if i["name"] == q) for q in "xyz"]
            inside[t] = [i["lower"] is not None and i["lower"] <= x[k] <= i["upper"] for k, i in enumerate(est)]
            if d["proven_intervals"] is not None:
                proven += 1
                box = d["proven_intervals"]["intervals"]
                proven_inside.append(all(b["lower"] <= x[k] <= b["upper"] for k, b in enumerate(box)))
                if est[2]["lower"] is not None:
                    ratios.append((box[2]["upper"] - box[2]["lower"]) / (est[2]["upper"] - est[2]["lower"]))
        per = "/".join(f"{v:.1%}" for v in inside.mean(axis=0))
        lines.append(f"  {name:>44} | {len(items):6d} | {per:>19} | {inside.all(axis=1).mean():10.1%} | "
                     f"{proven:6d} | {np.mean(proven_inside) if proven_inside else float('nan'):12.1%} | "
                     f"{np.median(ratios) if ratios else float('nan'):.2f}")
    return lines


def real_resection(rng, noise_px: float = 0.5, sizes: tuple[int, ...] = (20, 100)) -> list[str]:
    """Coverage of the true camera centre on real camera layouts: every camera of each real set
    (real_camera_sets), resected from ``size`` points drawn in the set's box that it sees (in front,
    inside the image), reprojected with noise_px of noise, with the defaults and a full
    certificate: the estimated centre intervals (each coordinate and all three), the proven ones
    (all three), the proven width over the estimate's (median over coordinates and cameras), and
    the proof's cost per camera (fractional.resection_sublevel) against its check's (the
    verifier's recomputation of the stated proof, verify_resection_sublevel), processor seconds."""
    from geocert.formulations.fractional.resection_sublevel import resection_sublevel, verify_resection_sublevel

    lines = [f"  {'scene':>40} | points | cameras | est. x/y/z coverage | est. all 3 | proven | proven all 3 | "
             "proven / est. width | proof ms | check ms"]
    for name, views, _, _ in real_camera_sets():
        if views.box is None:
            continue
        lower, upper = views.box
        width, height = views.image_size
        for size in sizes:
            inside, proven_inside, proven, ratios, proving, checking, count = [], [], 0, [], [], [], 0
            for camera, centre in zip(views.cameras, views.centres):
                X = rng.uniform(lower, upper, size=(20 * size, 3))
                proj = np.hstack([X, np.ones((len(X), 1))]) @ camera.T
                proj = proj * np.sign(np.median(proj[:, 2]))  # VGG's cameras put the scene at negative depth
                image = proj[:, :2] / proj[:, 2:3]
                seen = (proj[:, 2] > 0) & np.all((image >= 0) & (image <= [width, height]), axis=1)
                if seen.sum() < size:
                    continue
                X, image = X[seen][:size], image[seen][:size] + rng.normal(scale=noise_px, size=(size, 2))
                result = solve_job({"kind": "resection", "data": {"maps": [
                    {"source": X.tolist(), "target": image.tolist()}]}, "options": {"certificate": "full"}})
                item, d = result["maps"][0], result["maps"][0]["determinacy"]
                count += 1
                if d is None:
                    continue
                est = [next(i for i in d["intervals"] if i["name"] == q) for q in ("centre_x", "centre_y", "centre_z")]
                inside.append([i["lower"] is not None and i["lower"] <= centre[k] <= i["upper"]
                               for k, i in enumerate(est)])
                if d["proven_intervals"] is None:
                    continue
                proven += 1
                box = d["proven_intervals"]["intervals"]
                proven_inside.append(all(b["lower"] <= centre[k] <= b["upper"] for k, b in enumerate(box)))
                ratios += [(b["upper"] - b["lower"]) / (e["upper"] - e["lower"]) for b, e in zip(box, est)
                           if e["lower"] is not None]
                began = time.process_time()
                sublevel = resection_sublevel(X, image, item["matrix"], d["cost_increase"])
                proving.append(time.process_time() - began)
                began = time.process_time()
                verify_resection_sublevel(X, image, sublevel, np.array(item["matrix"]), "L2L2")
                checking.append(time.process_time() - began)
            covered = np.array(inside, dtype=bool).reshape(-1, 3)
            per = "/".join(f"{v:.1%}" for v in covered.mean(axis=0)) if len(covered) else "-"
            lines.append(f"  {name:>40} | {size:6d} | {count:7d} | {per:>19} | "
                         f"{covered.all(axis=1).mean() if len(covered) else float('nan'):10.1%} | {proven:6d} | "
                         f"{np.mean(proven_inside) if proven_inside else float('nan'):12.1%} | "
                         f"{np.median(ratios) if ratios else float('nan'):18.2f} | "
                         f"{1e3 * np.median(proving) if proving else float('nan'):8.1f} | "
                         f"{1e3 * np.median(checking) if checking else float('nan'):8.1f}")
    return lines


def real_resection_l1(rng, noise_px: float = 0.5, size: int = 20, per_set: int = 6) -> list[str]:
    """Proven intervals of L1 resections (fractional.resection_leaves) on real camera layouts: up
    to ``per_set`` cameras of each real set (real_camera_sets), resected from ``size`` points drawn
    in the set's box that it sees, noise_px of noise, under L1L1 and L2L1 with a full certificate:
    how often the true camera's depth row lies in the proven intervals (all four entries), their
    width over the estimate's error (|returned - true| depth row, median over entries and cameras),
    whether the verifier accepts the result, and the processor time of the solve against the same
    solve with a summary certificate (no second search): the ratio of the sums, both in this run."""
    lines = [f"  {'scene':>40} | norm | cameras | truth inside (all 4) | width / error | verified | "
             "CPU full / summary | centre proven, truth inside"]
    from geocert.verify.checks import verify_any

    for name, views, _, _ in real_camera_sets():
        if views.box is None:
            continue
        lower, upper = views.box
        width, height = views.image_size
        for norm in ("L1L1", "L2L1"):
            inside, ratios, verified, full_s, summary_s, count, centres = [], [], 0, 0.0, 0.0, 0, []
            for camera in views.cameras[:per_set]:
                X = rng.uniform(lower, upper, size=(20 * size, 3))
                proj = np.hstack([X, np.ones((len(X), 1))]) @ camera.T
                camera = camera * np.sign(np.median(proj[:, 2]))  # VGG's cameras put the scene at negative depth
                proj = np.hstack([X, np.ones((len(X), 1))]) @ camera.T
                image = proj[:, :2] / proj[:, 2:3]
                seen = (proj[:, 2] > 0) & np.all((image >= 0) & (image <= [width, height]), axis=1)
                if seen.sum() < size:
                    continue
                X, image = X[seen][:size], image[seen][:size] + rng.normal(scale=noise_px, size=(size, 2))
                job = {"kind": "resection", "data": {"maps": [{"source": X.tolist(), "target": image.tolist()}]},
                       "options": {"norm": norm, "certificate": "summary"}}
                began = time.process_time()
                solve_job(job)
                summary_s += time.process_time() - began
                job["options"]["certificate"] = "full"
                began = time.process_time()
                result = solve_job(job)
                full_s += time.process_time() - began
                count += 1
                d = result["maps"][0]["determinacy"]
                if d is None or d["proven_intervals"] is None:
                    inside.append(False)
                    continue
                verified += verify_any(result).valid
                reference = result["certificate"]["items"][0]["proof"]["sublevel"]["reference"]
                truth = camera[2] / (camera[2] @ np.append(X[reference], 1.0))
                returned = np.array(result["maps"][0]["matrix"])[2]
                returned = returned / (returned @ np.append(X[reference], 1.0))
                box = np.array([[i["lower"], i["upper"]] for i in d["proven_intervals"]["intervals"]])
                box, centre_box = box[:4], box[4:]  # the depth row, then the centre when proven
                inside.append(bool(np.all((box[:, 0] <= truth) & (truth <= box[:, 1]))))
                ratios += list((box[:, 1] - box[:, 0]) / np.maximum(np.abs(returned - truth), 1e-300))
                if len(centre_box):
                    true_centre = np.linalg.svd(camera)[2][-1]
                    true_centre = true_centre[:3] / true_centre[3]
                    centres.append(bool(np.all((centre_box[:, 0] <= true_centre) & (true_centre <= centre_box[:, 1]))))
            if count:
                lines.append(f"  {name:>40} | {norm} | {count:7d} | {np.mean(inside):20.1%} | "
                             f"{np.median(ratios) if ratios else float('nan'):13.1f} | {verified:4d}/{count:<3d} | "
                             f"{full_s / max(summary_s, 1e-9):18.1f} | {sum(centres)}/{len(centres)}")
    return lines


def synthetic_resection_l1(seeds: int = 20, size: int = 20, noise_px: float = 0.5) -> list[str]:
    """Proven intervals of L1 resections' camera centres (fractional.resection_centre_l1) on
    ``seeds`` synthetic cameras 10 units from ``size`` points in [-2, 2]^3 (bench.determinacy's
    resection scenes), noise_px of noise, under L1L1 and L2L1 with a full certificate; and the same
    points under L2L2 (its proven centre, fractional.resection_sublevel) for the widths: how often a
    centre interval is proven, holds the true centre (all 3 coordinates), the median width over
    L2L2's, the result verifying, and the processor time of a full certificate against a summary's
    (both in this run), and of the full certificate with the centre's proof switched off (the
    depth row alone, as before it), with the centre's own proof and its check apart."""
    from geocert.formulations.fractional.resection_centre_l1 import l1_centre, verify_l1_centre
    from geocert.verify.checks import verify_any

    lines = ["  norm | cameras | centre proven | truth inside | width / L2L2's (median, x y z) | verified | "
             "CPU full / summary | centre proof ms | its check ms (medians)"]
    for norm in ("L1L1", "L2L1"):
        rng = np.random.default_rng(37)
        proven = inside = verified = 0
        ratios, full_s, summary_s, depth_only_s, prove_ms, check_ms = [], 0.0, 0.0, 0.0, [], []
        for _ in range(seeds):
            centre = np.array([*rng.uniform(-2, 2, 2), -10.0])
            camera = cameras_looking_at_origin(centre[None, :])
            X = rng.uniform(-2, 2, size=(size, 3))
            image = np.array([project(camera, x)[0] for x in X]) + rng.normal(scale=noise_px, size=(size, 2))
            job = {"kind": "resection", "data": {"maps": [{"source": X.tolist(), "target": image.tolist()}]},
                   "options": {"norm": norm, "certificate": "summary", "detail": "full"}}
            began = time.process_time()
            solve_job(job)
            summary_s += time.process_time() - began
            job["options"]["certificate"] = "full"
            began = time.process_time()
            with mock.patch("geocert.solvers.fractional.maps.l1_centre", return_value=None):
                solve_job(job)  # the full certificate as before the centre: its depth row alone
            depth_only_s += time.process_time() - began
            began = time.process_time()
            result = solve_job(job)
            full_s += time.process_time() - began
            verified += verify_any(result).valid
            sublevel = result["certificate"]["items"][0]["proof"].get("sublevel") or {}
            if "centre" not in sublevel:
                continue
            proven += 1
            box = np.array(sublevel["centre"]["intervals"])
            inside += bool(np.all((box[:, 0] <= centre) & (centre <= box[:, 1])))
            M = np.array(result["maps"][0]["matrix"])
            began = time.process_time()
            l1_centre(X, image, M, norm, sublevel["cost_increase"], sublevel["reference"])
            prove_ms.append(1e3 * (time.process_time() - began))
            began = time.process_time()
            verify_l1_centre(X, image, sublevel["centre"], M, norm, sublevel["cost_increase"], sublevel["reference"])
            check_ms.append(1e3 * (time.process_time() - began))
            job["options"].update(norm="L2L2", certificate="summary")
            l2 = solve_job(job)["maps"][0]["determinacy"]["proven_intervals"]
            if l2 is not None:
                l2_box = np.array([[i["lower"], i["upper"]] for i in l2["intervals"]])
                ratios.append((box[:, 1] - box[:, 0]) / (l2_box[:, 1] - l2_box[:, 0]))
        ratio = " ".join(f"{v:.2f}" for v in np.median(ratios, axis=0)) if ratios else "n/a"
        lines.append(f"  {norm} | {seeds:7d} | {proven:13d} | {inside:12d} | {ratio:>30} | {verified:5d}/{seeds} | "
                     f"{full_s / max(summary_s, 1e-9):5.2f} ({depth_only_s / max(summary_s, 1e-9):.2f} without the "
                     f"centre) | {np.median(prove_ms) if prove_ms else float('nan'):15.1f} | "
                     f"{np.median(check_ms) if check_ms else float('nan'):.1f}")
    return lines


def direct_views_proven(seeds: int = 6, views: int = 6) -> list[str]:
    """The direct method's proven interval of each view's focal length (varying_focal,
    direct_sublevel.check_views) on Table 7.1's varying-focal protocol (f in [0.05, 1] a view, 0.2%
    noise, ``views`` views, chirality "centers"), seeds 0 .. ``seeds`` - 1: whether the stage
    certifies and every end is proven, the result verifying, how many views' intervals hold the
    true focal length, the returned one, and the true quadric's (which they must when its cost is
    within the level), the median half-width over the value (proven, and the curvature estimate's),
    and the processor time of the job with the proof against without it, and of its verification."""
    from geocert.formulations.autocalibration import direct, direct_relaxation
    from geocert.formulations.autocalibration import problem as autocalibration_problem
    from geocert.formulations.autocalibration.proofs import sublevel_level
    from geocert.verify.checks import verify_any

    intrinsics = {"aspect": [0.95, 1.05], "skew": [-0.01, 0.01], "principal_point": [[-0.1, 0.1], [-0.1, 0.1]],
                  "focal": [0.05, 1.0]}

    def quantity(w):
        return float(np.sqrt((w[0, 0] + w[1, 1]) / (2.0 * w[2, 2])))

    lines = [f"  seed | certified, ends proven | verified | true f inside | returned inside | true Q within level: "
             f"its f inside | half-width / f, proven (estimate) median | CPU s job with / without | verify s"]
    for seed in range(seeds):
        scene, Ks = scenes.table71_scene(seed, 0.2, True, views=views)
        job = {"kind": "autocalibration", "data": {"cameras": scene.cameras.tolist(), "points": scene.points.tolist()},
               "options": {"method": "direct", "varying_focal": True, "intrinsics": intrinsics, "chirality": "centers",
                           "certificate": "full", "time_limit_s": 3600}}
        began = time.process_time()
        solve_job(job)
        without_s = time.process_time() - began
        job["options"]["prove_focal_interval"] = True
        began = time.process_time()
        result = solve_job(job)
        with_s = time.process_time() - began
        began = time.process_time()
        valid = verify_any(result).valid
        verify_s = time.process_time() - began
        stage = result["stages"][0]
        proof = result["certificate"]["items"][0].get("proof") or {}
        sublevel = proof.get("sublevel")
        if sublevel is None:
            lines.append(f"  {seed:4d} | {stage['certified']!s:>5}, no proof | {valid!s:>8} | CPU {with_s:.1f} / "
                         f"{without_s:.1f}")
            continue
        ends = sum(v["lower"] is not None for v in sublevel["views"]) + sum(v["upper"] is not None
                                                                          for v in sublevel["views"])
        bounds = [(i["lower"], i["upper"]) for i in stage["determinacy"]["proven_intervals"]["intervals"]]
        Q_returned = np.array(result["dual_absolute_quadric"])
        Hi = np.linalg.inv(scene.projective)
        true_Q = Hi @ np.diag([1.0, 1.0, 1.0, 0.0]) @ Hi.T
        setup = direct.setup_for(autocalibration_problem.prepare(scene.cameras, scene.points, None, intrinsics),
                                 "centers")
        within = direct_relaxation.cost(setup.cameras, setup.from_input(true_Q)) <= sublevel_level(
            stage["cost"], sublevel["cost_increase"])
        true_in = sum(lo <= K[0, 0] <= hi for (lo, hi), K in zip(bounds, Ks))
        returned_in = sum(lo <= quantity(P @ Q_returned @ P.T) <= hi for (lo, hi), P in zip(bounds, scene.cameras))
        true_q_in = sum(lo <= quantity(P @ true_Q @ P.T) <= hi for (lo, hi), P in zip(bounds, scene.cameras))
        half = np.median([(hi - lo) / 2 / K[0][0] for (lo, hi), K in zip(bounds, result["Ks"])])
        estimate = np.median([(i["upper"] - i["lower"]) / 2 / i["value"] for i in stage["determinacy"]["intervals"]
                              if i["upper"] is not None and i["lower"] is not None] or [np.nan])
        lines.append(f"  {seed:4d} | {stage['certified']!s:>5}, {ends:2d}/{2 * views} | {valid!s:>8} | "
                     f"{true_in:2d}/{views} | {returned_in:2d}/{views} | {within!s:>5}: {true_q_in:2d}/{views} | "
                     f"{half:.3f} ({estimate:.3f}) | {with_s:6.1f} / {without_s:4.1f} | {verify_s:.1f}")
    return lines


def direct_views_proven_real(noise_px: float = 0.5) -> list[str]:
    """direct_views_proven on the Oxford Model House's cameras (VGG's, each view its own K), moved
    to a random projective frame with ``noise_px`` of noise (scenes.from_cameras), with the
    intrinsics ranges the image size gives: each view's proven interval against its own K's
    quantity, f0 sqrt((f_x^2 + f_y^2 + s^2 + (u - u0)^2 + (v - v0)^2) / 2), (u0, v0) the ranges'
    middle, and against the true quadric's."""
    from geocert.solvers import datasets
    from geocert.formulations.autocalibration import direct, direct_relaxation, direct_sublevel
    from geocert.formulations.autocalibration import problem as autocalibration_problem
    from geocert.formulations.autocalibration.proofs import sublevel_level
    from geocert.verify.checks import verify_any

    if not (SHARED_DATA / "oxford_house").exists():
        return ["  the Oxford Model House is absent (shared/data/oxford_house)"]
    views = datasets.load_vgg_cameras(SHARED_DATA / "oxford_house", "house", (768, 576))
    scene = scenes.from_cameras(views.cameras, views.box, noise_px, seed=0, image_size=views.image_size)
    job = {"kind": "autocalibration", "data": scene.job_data(),
           "options": {"method": "direct", "varying_focal": True, "chirality": "centers", "certificate": "full",
                       "prove_focal_interval": True, "time_limit_s": 3600}}
    began = time.process_time()
    result = solve_job(job)
    spent = time.process_time() - began
    stage = result["stages"][0]
    sublevel = (result["certificate"]["items"][0].get("proof") or {}).get("sublevel")
    head = f"  Model House, {len(views.cameras)} views: certified {stage['certified']}, verified " \
           f"{verify_any(result).valid}, {spent:.0f} s of CPU"
    if sublevel is None:
        return [head + "; no proof"]
    problem = autocalibration_problem.prepare(scene.cameras, scene.points, scene.image_size, {})
    setup = direct.setup_for(problem, "centers")
    K0, f0 = problem.K0, float(problem.K0[0, 0])
    Hi = np.linalg.inv(scene.projective)
    true_Q = setup.from_input(Hi @ np.diag([1.0, 1.0, 1.0, 0.0]) @ Hi.T)
    within = direct_relaxation.cost(setup.cameras, true_Q) <= sublevel_level(stage["cost"], sublevel["cost_increase"])
    lines = [head + f"; the true quadric within the level: {within}",
             "  view | proven [lower, upper] px | its K's quantity | the true quadric's | the returned Ks[k]'s fx"]
    for k, interval in enumerate(stage["determinacy"]["proven_intervals"]["intervals"]):
        K = views.K[k] / views.K[k][2, 2]
        truth = float(np.sqrt((K[0, 0] ** 2 + K[1, 1] ** 2 + K[0, 1] ** 2 + (K[0, 2] - K0[0, 2]) ** 2
                               + (K[1, 2] - K0[1, 2]) ** 2) / 2))
        quadric = direct_sublevel.focal_of(setup.cameras, true_Q, f0, k)
        lines.append(f"  {k:4d} | [{interval['lower']:.0f}, {interval['upper']:.0f}] | {truth:.0f} "
                     f"{'in' if interval['lower'] <= truth <= interval['upper'] else 'OUT'} | {quadric:.0f} "
                     f"{'in' if interval['lower'] <= quadric <= interval['upper'] else 'OUT'} | "
                     f"{result['Ks'][k][0][0]:.0f}")
    return lines


def direct_intrinsics_proven_real(noise_px: float = 0.5) -> list[str]:
    """The direct method's proven intervals of the other intrinsics (one K,
    prove_intrinsics_intervals) on the Oxford Model House's cameras (VGG's), moved to a random
    projective frame with ``noise_px`` of noise, the ranges the image size gives: each interval
    against the spread of VGG's ten Ks (their least and greatest value of the quantity) and the K
    returned."""
    from geocert.solvers import datasets
    from geocert.verify.checks import verify_any

    if not (SHARED_DATA / "oxford_house").exists():
        return ["  the Oxford Model House is absent (shared/data/oxford_house)"]
    views = datasets.load_vgg_cameras(SHARED_DATA / "oxford_house", "house", (768, 576))
    scene = scenes.from_cameras(views.cameras, views.box, noise_px, seed=0, image_size=views.image_size)
    job = {"kind": "autocalibration", "data": scene.job_data(),
           "options": {"method": "direct", "chirality": "centers", "certificate": "full",
                       "prove_intrinsics_intervals": True, "time_limit_s": 3600}}
    began = time.process_time()
    result = solve_job(job)
    spent = time.process_time() - began
    stage = result["stages"][0]
    proven = (stage.get("determinacy") or {}).get("proven_intervals")
    head = f"  Model House, {len(views.cameras)} views: certified {stage['certified']}, verified " \
           f"{verify_any(result).valid}, {spent:.0f} s of CPU"
    if not proven:
        return [head + "; no proven intervals"]
    Ks = [K / K[2, 2] for K in views.K]
    of_K = {"focal": lambda K: K[0, 0], "principal_u": lambda K: K[0, 2], "principal_v": lambda K: K[1, 2],
            "focal_y": lambda K: K[1, 1], "skew": lambda K: K[0, 1], "aspect": lambda K: K[1, 1] / K[0, 0]}
    returned = np.asarray(result.get("K") or result["Ks"][0], dtype=float)
    lines = [head, "  quantity | proven [lower, upper] | VGG's Ks, least .. greatest | inside | returned K's"]
    for interval in proven["intervals"]:
        name, lo, hi = interval["name"], interval["lower"], interval["upper"]
        read = of_K.get(name.split("[")[0])
        if read is None:
            continue
        values = [float(read(K)) for K in Ks]
        inside = sum((lo is None or lo <= v) and (hi is None or v <= hi) for v in values)
        text = f"[{'-inf' if lo is None else f'{lo:.4g}'}, {'inf' if hi is None else f'{hi:.4g}'}]"
        lines.append(f"  {name:>11} | {text:>22} | {min(values):.4g} .. {max(values):.4g} | {inside:2d}/{len(values)} | "
                     f"{float(read(returned / returned[2, 2])):.4g}"
                     + (f" ({interval['reason']})" if interval.get("reason") else ""))
    return lines


def lone_tracks(noise_px: float = 0.5, count: int = 800, seeds: tuple[int, ...] = (11, 12, 13, 14)) -> list[str]:
    """A user's lone point: jobs of one 2-view track (the first two views of ``count`` of the
    Dinosaur's own tracks, their certified points the truth, reprojected with noise_px), against
    the same tracks in one job (pooled): how many are `determined`, and how many of those miss."""
    from geocert.solvers import datasets

    if not (SHARED_DATA / "oxford_dinosaur").exists():
        return ["  the Oxford Dinosaur is absent (shared/data/oxford_dinosaur)"]
    cameras, tracks = datasets.load_dinosaur(SHARED_DATA / "oxford_dinosaur")
    lines = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        chosen = rng.choice(len(tracks), count, replace=False)
        truth = np.array([t["point"] for t in solve_job({"kind": "triangulation", "data": {
            "cameras": cameras.tolist(), "tracks": [{"views": tracks[i].views, "points": tracks[i].points.tolist()}
                                                    for i in chosen]}, "options": {"detail": "brief"}})["tracks"]])
        lone = [{"views": list(map(int, tracks[i].views[:2])),
                 "points": (project(cameras[tracks[i].views[:2]], X) + rng.normal(scale=noise_px, size=(2, 2))).tolist()}
                for i, X in zip(chosen, truth)]
        for how in ("alone", "pooled"):
            items = [solve_job({"kind": "triangulation", "data": {"cameras": cameras.tolist(), "tracks": [t]},
                                "options": {}})["tracks"][0] for t in lone] if how == "alone" else solve_job(
                {"kind": "triangulation", "data": {"cameras": cameras.tolist(), "tracks": lone}, "options": {}})["tracks"]
            determined = missed = warned = 0
            for item, X in zip(items, truth):
                d = item["determinacy"]
                if d is None:
                    continue
                warned += "few_degrees_of_freedom" in [w["code"] for w in d["warnings"]]
                if d["determined"]:
                    determined += 1
                    missed += not all(i["lower"] <= X[k] <= i["upper"] for k, i in enumerate(d["intervals"][:3]))
            lines.append(f"  seed {seed}, {how}: {len(items)} tracks, few_degrees_of_freedom {warned}, determined "
                         f"{determined}, of which missing the truth {missed}")
    return lines


def critical_real_layouts(noise_px: float = 0.5) -> list[str]:
    """Real near-critical layouts autocalibrated with the defaults: rings with elevation change
    (16 of the dino hemisphere's views within an elevation band, two draws a band) and KITTI
    windows (every 2nd of the set's views from the first, up to 12; every 4th, 7; 15 consecutive from
    the 11th; points ahead of the last view):
    each stage's warnings and `determined`."""
    from geocert.solvers import datasets
    from testing import photo_sets

    lines, jobs = [], []
    hemisphere = BENCH_DATA / "middlebury_dino_cameras"
    if hemisphere.exists():
        views = datasets.load_middlebury(hemisphere)
        d = views.centres - (views.box[0] + views.box[1]) / 2
        up = d.mean(axis=0) / np.linalg.norm(d.mean(axis=0))
        elevation = np.degrees(np.arcsin(d @ up / np.linalg.norm(d, axis=1)))
        for lo, hi in ((10, 20), (25, 35), (40, 50)):
            band = np.flatnonzero((elevation >= lo) & (elevation < hi))
            for seed in (0, 1):
                chosen = views.subset(np.random.default_rng(seed).choice(band, 16, replace=False))
                jobs.append((f"hemisphere ring {lo}-{hi} deg (seed {seed})", chosen.cameras, chosen.box,
                             chosen.image_size, seed, {"focal": [1000.0, 6000.0]}))
    for key, size in (("kittiStraight", (1226, 370)), ("kittiTurn", (1241, 376))):
        try:
            chosen = photo_sets.load(key)
        except photo_sets.MissingSet:
            continue
        cameras = [chosen.truth[name] for name in chosen.names]
        for start, step, m in ((0, 2, 12), (0, 4, 12), (10, 1, 15)):
            part = cameras[start::step][:m]
            P = np.array([c.K @ np.hstack([c.R, c.t[:, None]]) for c in part])
            ahead = np.array([part[-1].center + part[-1].R[2] * z for z in (8.0, 60.0)])
            box = (ahead.min(axis=0) - [12, 3, 12], ahead.max(axis=0) + [12, 3, 12])
            jobs.append((f"{key}, frames {start}::{step}, {len(part)} views", P, box, size, 0, None))
    for name, cameras, box, size, seed, intrinsics in jobs:
        scene = scenes.from_cameras(cameras, box, noise_px, seed=seed, image_size=size)
        result = solve_job({"kind": "autocalibration", "data": scene.job_data(),
                            "options": {"time_limit_s": 10, **({"intrinsics": intrinsics} if intrinsics else {})}})
        said = "; ".join(f"{s['name']}: {[w['code'] for w in s['determinacy']['warnings']]} determined "
                         f"{s['determinacy']['determined']}" for s in result["stages"] if s.get("determinacy"))
        lines.append(f"  {name}: {said}")
    return lines


def report(title: str, rows: dict, flagged: int | None, n: int, degenerate: str, caught: int, m: int) -> None:
    print(f"\n{title}")
    print(f"  {'quantity':>14} | {'coverage':>8} | {'median width':>12} | {'median |error|':>14} | unbounded | "
          "fixing (10%) | their coverage")
    for name, row in rows.items():
        bounded = row["n"] - row["unbounded"]
        coverage = row["inside"] / bounded if bounded else float("nan")
        fixing = row["fixing_inside"] / row["fixing"] if row["fixing"] else float("nan")
        print(f"  {name:>14} | {coverage:8.1%} | {np.median(row['widths']) if row['widths'] else float('nan'):12.4g} | "
              f"{np.median(row['errors']) if row['errors'] else float('nan'):14.4g} | {row['unbounded']}/{row['n']} | "
              f"{row['fixing']}/{row['n']} | {fixing:.1%}")
    if flagged is not None:
        print(f"  well-posed scenes flagged: {flagged}/{n}; {degenerate} flagged: {caught}/{m}")


def autocalibration_proven(noise_px: float = 0.5, synthetic: int = 5) -> list[str]:
    """The metric stage's proven intervals (a full certificate) on each real set, as
    real_autocalibration solves it, and on ``synthetic`` scenes of 8 views (make_scene, 0.5%
    noise): each job solved with certificate "summary", "full" without the proven intervals'
    search, "full", then "full" with options.prove_intervals_over_planes, its CPU time
    (process_time) in each and the ratios; whether the proven intervals hold the truth (for the
    plane stated: on a critical motion that plane is one of a family; and over planes), against
    the estimate's; and whether the last result verifies."""
    from geocert.verify.checks import verify_any

    jobs = []
    for name, views, critical, intrinsics in real_camera_sets():
        scene = scenes.from_cameras(views.cameras, views.box, noise_px, seed=0, image_size=views.image_size)
        jobs.append((name, scene, intrinsics))
    for seed in range(1, synthetic + 1):
        jobs.append((f"synthetic sphere, 8 views, 0.5% (seed {seed})", scenes.make_scene(8, 0.5, points=60, seed=seed),
                     {}))
    lines, covered, total, estimated, over, over_total = [], 0, 0, 0, 0, 0
    cpu = {"summary": 0.0, "proofs": 0.0, "full": 0.0, "over_planes": 0.0}
    for name, scene, intrinsics in jobs:
        spent = {}
        for run in ("summary", "proofs", "full", "over_planes"):
            # "proofs": a full certificate without the proven intervals' search (the kind's step
            # that runs it made a no-op), so that what the intervals add shows apart from the proofs
            skip = mock.patch("geocert.kinds.autocalibration._prove_intervals") if run == "proofs" \
                else contextlib.nullcontext()
            began = time.process_time()
            with skip:
                result = solve_job({"kind": "autocalibration", "data": scene.job_data(),
                                    "options": {"certificate": "summary" if run == "summary" else "full",
                                                "prove_intervals_over_planes": run == "over_planes",
                                                **({"intrinsics": intrinsics} if intrinsics else {})}})
            spent[run] = time.process_time() - began
            cpu[run] += spent[run]
        timing = (f"CPU summary {spent['summary']:.1f} s, full without intervals {spent['proofs']:.1f} s, full "
                  f"{spent['full']:.1f} s (x{spent['full'] / spent['summary']:.2f}), with intervals over planes "
                  f"{spent['over_planes']:.1f} s (x{spent['over_planes'] / spent['full']:.2f} a full one's)")
        d = result["stages"][1].get("determinacy")
        if d is None or d.get("proven_intervals") is None:
            lines.append(f"  {name}: no proven intervals (metric stage {result['stages'][1]['status']}); {timing}")
            continue
        K = scene.K / scene.K[2, 2]
        truth = {"focal_x": K[0, 0], "focal_y": K[1, 1], "skew": K[0, 1], "principal_u": K[0, 2],
                 "principal_v": K[1, 2]}
        proven = {i["name"]: i for i in d["proven_intervals"]["intervals"]}
        estimate = {i["name"]: i for i in d["intervals"]}
        inside = [n for n, i in proven.items() if i["lower"] <= truth[n] <= i["upper"]]
        planes = {i["name"]: i for i in (d.get("proven_over_planes") or {}).get("intervals", [])}
        inside_planes = [n for n, i in planes.items() if i["lower"] <= truth[n] <= i["upper"]]
        over, over_total = over + len(inside_planes), over_total + len(planes)
        inside_estimate = [n for n, i in estimate.items() if i["lower"] is not None and i["upper"] is not None
                           and i["lower"] <= truth[n] <= i["upper"]]
        covered, total, estimated = covered + len(inside), total + 5, estimated + len(inside_estimate)
        f, fe = proven["focal_x"], estimate["focal_x"]

        def end(x):
            return "unbounded" if x is None else f"{x:.0f}"

        lines.append(f"  {name}: f {result['K'][0][0]:.0f} px (truth {K[0, 0]:.0f}); proven focal_x "
                     f"[{end(f['lower'])}, {end(f['upper'])}], estimate [{end(fe['lower'])}, {end(fe['upper'])}]; "
                     f"truth inside proven {len(inside)}/5, proven over planes {len(inside_planes)}/{len(planes)}, "
                     f"estimate {len(inside_estimate)}/5; verifies "
                     f"{verify_any(result).valid}; {timing}")
    lines.append(f"  all: the truth inside the proven intervals {covered}/{total}, those proven over planes "
                 f"{over}/{over_total}, the estimate's {estimated}/{total}; "
                 f"CPU summary {cpu['summary']:.1f} s, full without intervals {cpu['proofs']:.1f} s, full "
                 f"{cpu['full']:.1f} s (x{cpu['full'] / cpu['summary']:.2f} a summary's, "
                 f"x{cpu['full'] / cpu['proofs']:.2f} without the intervals), with intervals over planes "
                 f"{cpu['over_planes']:.1f} s (x{cpu['over_planes'] / cpu['full']:.2f} a full one's)")
    return lines


def _section(title: str, lines, began: float) -> None:
    """One section of the bench alone: its title with the load, its lines, the wall time."""
    print(f"{title}; load {open('/proc/loadavg').read().split()[0]}")
    print("\n".join(lines()))
    print(f"\nWall time {time.perf_counter() - began:.0f} s; load {open('/proc/loadavg').read().split()[0]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", type=int, default=40)
    parser.add_argument("--autocalibration-scenes", type=int, default=10)
    parser.add_argument("--no-real", action="store_true", help="skip the real camera sets (bench-data, shared/data)")
    parser.add_argument("--triangulation-only", action="store_true",
                        help="the real camera sets' triangulation coverage only (estimated and proven intervals)")
    parser.add_argument("--resection-l1", action="store_true",
                        help="the real camera sets' L1 resections only: their proven depth-row intervals (issue 37)")
    parser.add_argument("--resection-l1-synthetic", action="store_true",
                        help="L1 resections' proven centres on 20 synthetic cameras (issue 37)")
    parser.add_argument("--resection-only", action="store_true",
                        help="the real camera sets' resection coverage only (estimated and proven intervals)")
    parser.add_argument("--autocalibration-proven", action="store_true",
                        help="the metric stage's proven intervals (real sets, synthetic scenes) against the "
                             "estimate's and the truth, and a full certificate's CPU against a summary's")
    parser.add_argument("--direct-views-proven", type=int, metavar="VIEWS", default=None,
                        help="the direct method's proven focal length of each view (varying_focal), Table 7.1's "
                             "protocol with VIEWS views, seeds 0 .. --autocalibration-scenes - 1")
    parser.add_argument("--direct-views-proven-real", action="store_true",
                        help="the same on the Oxford Model House's cameras")
    parser.add_argument("--direct-intrinsics-proven-real", action="store_true",
                        help="the direct method's proven intrinsics (one K) on the Oxford Model House's cameras")
    parser.add_argument("--lone-tracks", action="store_true",
                        help="jobs of one 2-view track on the Dinosaur's cameras, against the same tracks pooled")
    parser.add_argument("--critical-real", action="store_true",
                        help="autocalibration of real near-critical layouts: hemisphere elevation bands, KITTI windows")
    args = parser.parse_args()
    rng = np.random.default_rng(19)
    began = time.perf_counter()
    if args.lone_tracks:
        return _section("Lone 2-view tracks on the Dinosaur's cameras (0.5 px)", lone_tracks, began)
    if args.critical_real:
        return _section("Real near-critical layouts (0.5 px): each stage's warnings", critical_real_layouts, began)
    if args.direct_intrinsics_proven_real:
        return _section("Direct autocalibration, one K, real cameras (0.5 px): its proven intrinsics",
                        direct_intrinsics_proven_real, began)
    if args.direct_views_proven_real:
        return _section("Direct autocalibration, one focal length a view, real cameras (0.5 px): its proven intervals",
                        direct_views_proven_real, began)
    if args.direct_views_proven is not None:
        return _section(f"Direct autocalibration, one focal length a view: its proven intervals "
                        f"({args.direct_views_proven} views, 0.2% noise)",
                        lambda: direct_views_proven(args.autocalibration_scenes, args.direct_views_proven), began)
    if args.resection_l1_synthetic:
        return _section("L1 resections' proven centres on synthetic cameras (20 points, 0.5 px noise)",
                        synthetic_resection_l1, began)
    if args.resection_l1:
        print(f"L1 resections on real camera sets (20 points drawn in the set's box, 0.5 px noise); load "
              f"{open('/proc/loadavg').read().split()[0]}")
        print("\n".join(real_resection_l1(np.random.default_rng(37))))
        print(f"\nWall time {time.perf_counter() - began:.0f} s")
        return
    if args.autocalibration_proven:
        print(f"Autocalibration (real cameras at 0.5 px, synthetic scenes): the metric stage's proven intervals, "
              f"for the plane stated, and a full certificate's CPU against a summary's; load "
              f"{open('/proc/loadavg').read().split()[0]}")
        print("\n".join(autocalibration_proven()))
        print(f"\nWall time {time.perf_counter() - began:.0f} s; load {open('/proc/loadavg').read().split()[0]}")
        return
    if args.resection_only:
        print("Resection on real camera sets (points drawn in the set's box, 0.5 px noise): the true centre's coverage")
        print("\n".join(real_resection(np.random.default_rng(37))))
        print(f"\nWall time {time.perf_counter() - began:.0f} s")
        return
    if args.triangulation_only:
        print("Triangulation on real camera sets (true points reprojected, 0.5 px noise): coverage of the truth")
        print("\n".join(real_triangulation(np.random.default_rng(37))))
        print(f"\nWall time {time.perf_counter() - began:.0f} s")
        return
    rows, flagged, caught = triangulation(args.scenes, rng)
    report("Triangulation (2 to 7 views, 1 px noise): x, y, z", rows, flagged, args.scenes,
           "near-zero parallax tracks", caught, args.scenes)
    rows, flagged, caught = resection(args.scenes, rng)
    report("Resection (8 to 30 points, 0.5 px noise): the camera centre", rows, flagged, args.scenes,
           "nearly coplanar points", caught, args.scenes)
    n = args.autocalibration_scenes
    rows, flagged, caught = autocalibration(n, rng)
    report("Autocalibration (10 and 20 views all round, 0.5% noise): the metric stage's K, pixels", rows, flagged,
           n, "turntable rings", caught, n)
    if not args.no_real:
        print("\nTriangulation on real camera sets (true points reprojected, 0.5 px noise): coverage of the truth")
        print("\n".join(real_triangulation(np.random.default_rng(37))))
        print("\nResection on real camera sets (points drawn in the set's box, 0.5 px noise): the true centre's "
              "coverage")
        print("\n".join(real_resection(np.random.default_rng(37))))
        rows, lines = real_autocalibration()
        report("Autocalibration on real cameras (ground truth moved to a projective frame, 0.5 px): the general "
               "motions' metric K, pixels", rows, None, 0, "", 0, 0)
        print("\n".join(lines))
    print(f"\nWall time {time.perf_counter() - began:.0f} s")


if __name__ == "__main__":
    main()
