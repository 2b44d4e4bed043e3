"""Where the features and matches stage's CPU goes, beside COLMAP's on the same photos (issue 35).

geocert's stage run piece by piece in this process, one piece at a time in one worker thread (the
stage's pieces run in its two threads, never the main one), process CPU seconds, the repeats'
median: decoding the photos (grayscale, as decode_image does), SIFT
(features.image_features), the descriptor distances and ratio test of every pair (features._match)
and the fundamental matrix's RANSAC (features.fit_fundamental), split between the pairs it verifies
and those it rejects (fewer than ``min_inliers`` inliers: MAGSAC++ runs to its iteration cap on
them); then, with --caps, what a lower RANSAC cap would save and which verdicts it would change
(pairs lost, passing pairs whose inliers differ). COLMAP's side (pycolmap, the bench extra) in a
child process, every core as bench/colmap_baseline.py runs it: SIFT extraction and exhaustive
matching with geometric verification, the child's CPU (user + system, every thread), its keypoints
an image and the pairs it verifies. Also SIFT on every photo in the main thread, user and system
CPU and minor page faults apart: there glibc's allocator hands each image's scale space back to
the system and faults it in again (about 280,000 faults, 0.5 s of system CPU on templeSparseRing's
16 photos), which a worker thread's arena does not.

    .venv/bin/python -m bench.features_vs_colmap [--set templeSparseRing] [--data DIR] [--repeats 3]
        [--caps 1000,2000] [--no-colmap]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

from testing import photo_sets

COLMAP_CHILD = r"""
import json, shutil, sqlite3, sys, time, resource
from pathlib import Path
import pycolmap
work, paths = sys.argv[1], json.loads(sys.argv[2])
images = Path(work) / "images"
images.mkdir()
for p in paths:
    shutil.copy(p, images / Path(p).name)
def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime
db = str(Path(work) / "database.db")
t0 = cpu()
pycolmap.extract_features(db, str(images), device=pycolmap.Device.cpu)
t1 = cpu()
pycolmap.match_exhaustive(db, device=pycolmap.Device.cpu)
t2 = cpu()
con = sqlite3.connect(db)
keypoints = [r[0] for r in con.execute("select rows from keypoints")]
verified = con.execute("select count(*) from two_view_geometries where rows >= 15").fetchone()[0]
print(json.dumps({"extract_cpu_s": t1 - t0, "match_cpu_s": t2 - t1, "keypoints": keypoints,
                  "verified_pairs": verified}))
"""


def colmap_side(paths: list[str]) -> dict:
    with tempfile.TemporaryDirectory(prefix="geocert-features-") as work:
        env = {**os.environ, "GLOG_minloglevel": "2"}
        done = subprocess.run([sys.executable, "-c", COLMAP_CHILD, work, json.dumps(paths)], capture_output=True,
                              text=True, env=env)
        if done.returncode != 0:
            return {"error": (done.stderr or done.stdout).strip()[-300:]}
        return json.loads(done.stdout.strip().splitlines()[-1])


def geocert_side(paths: list[str], caps: list[int]) -> dict:
    import cv2

    from geocert.pipelines.reconstruction import features
    from geocert.pipelines.reconstruction.options import FeatureOptions

    options = FeatureOptions()
    cpu = time.process_time
    raw = [open(p, "rb").read() for p in paths]
    t = cpu()
    images = [cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE) for data in raw]
    figures = {"decode": cpu() - t}
    t = cpu()
    found = [features.image_features(options, image) for image in images]
    figures["sift"] = cpu() - t
    keypoints, descriptors = [k for k, _ in found], [d for _, d in found]
    pairs = [(i, j) for i in range(len(images)) for j in range(i + 1, len(images))]
    t = cpu()
    rows = {pair: features._match(descriptors[pair[0]], descriptors[pair[1]], options) for pair in pairs}
    figures["distances_and_ratio_test"] = cpu() - t

    def ransac(opts):
        spent, masks = {"verified": 0.0, "rejected": 0.0}, {}
        for i, j in pairs:
            r = rows[(i, j)]
            t = cpu()
            _, inliers = features.fit_fundamental(keypoints[i][r[:, 0]], keypoints[j][r[:, 1]], opts)
            spent["verified" if inliers.sum() >= options.min_inliers else "rejected"] += cpu() - t
            masks[(i, j)] = inliers
        return spent, masks

    spent, masks = ransac(options)
    figures.update({"ransac_verified": spent["verified"], "ransac_rejected": spent["rejected"]})
    passing = [p for p in pairs if masks[p].sum() >= options.min_inliers]
    counts = {"keypoints": [len(k) for k in keypoints], "pairs": len(pairs), "verified_pairs": len(passing),
              "rejected_with_matches": sum(1 for p in pairs
                                           if p not in passing and len(rows[p]) >= options.min_inliers)}
    trials = {}
    for cap in caps:
        cap_spent, cap_masks = ransac(dataclasses.replace(options, ransac_max_iters=cap))
        trials[cap] = {"cpu_s": cap_spent["verified"] + cap_spent["rejected"],
                       "lost": [[list(p), int(cap_masks[p].sum()), int(masks[p].sum())] for p in passing
                                if cap_masks[p].sum() < options.min_inliers],
                       "gained": [list(p) for p in pairs if p not in passing
                                  and cap_masks[p].sum() >= options.min_inliers],
                       "passing_changed": sum(1 for p in passing if not np.array_equal(cap_masks[p], masks[p]))}
    return {"cpu_s": figures, "counts": counts, "caps": trials}


def sift_main_thread(paths: list[str]) -> dict:
    """SIFT on every photo, one after the other in this (the main) thread: user and system CPU and
    minor page faults."""
    import cv2

    from geocert.pipelines.reconstruction import features
    from geocert.pipelines.reconstruction.options import FeatureOptions

    options = FeatureOptions()
    images = [cv2.imread(p, cv2.IMREAD_GRAYSCALE) for p in paths]
    before = resource.getrusage(resource.RUSAGE_SELF)
    for image in images:
        features.image_features(options, image)
    after = resource.getrusage(resource.RUSAGE_SELF)
    return {"user_s": after.ru_utime - before.ru_utime, "system_s": after.ru_stime - before.ru_stime,
            "minor_faults": after.ru_minflt - before.ru_minflt}


def in_a_worker_thread(function, *args):
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=1) as pool:
        return pool.submit(function, *args).result()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--set", default="templeSparseRing", help="a photo set of testing/photo_sets.py")
    parser.add_argument("--data", default=None, help="data root (default $GEOCERT_BENCH_DATA)")
    parser.add_argument("--repeats", type=int, default=3, help="geocert's pieces run this many times (median)")
    parser.add_argument("--caps", default="", help="comma-separated RANSAC iteration caps to compare")
    parser.add_argument("--no-colmap", action="store_true", help="geocert's side only")
    args = parser.parse_args(argv)
    photo_set = photo_sets.load(args.set, args.data)
    paths = [str(photo_set.path(n)) for n in photo_set.names]
    caps = [int(c) for c in args.caps.split(",") if c]
    print(f"{args.set}: {len(paths)} photos; load {os.getloadavg()[0]:.1f} at start")
    runs = [in_a_worker_thread(geocert_side, paths, caps if k == 0 else []) for k in range(args.repeats)]
    for name in runs[0]["cpu_s"]:
        values = [run["cpu_s"][name] for run in runs]
        print(f"  geocert {name}: {np.median(values):.2f} s CPU (runs {', '.join(f'{v:.2f}' for v in values)})")
    print(f"  geocert total: {np.median([sum(run['cpu_s'].values()) for run in runs]):.2f} s CPU")
    counts = runs[0]["counts"]
    print(f"  geocert keypoints an image {np.mean(counts['keypoints']):.0f}, pairs {counts['pairs']}, verified "
          f"{counts['verified_pairs']}, rejected with at least min_inliers matches {counts['rejected_with_matches']}")
    for cap, trial in runs[0]["caps"].items():
        print(f"  RANSAC cap {cap}: {trial['cpu_s']:.2f} s CPU; verified pairs lost (inliers at the cap, at the "
              f"default) {trial['lost']}, gained {trial['gained']}, verified pairs whose inliers change "
              f"{trial['passing_changed']}")
    main_thread = [sift_main_thread(paths) for _ in range(args.repeats)]
    print("  SIFT in the main thread: " + "; ".join(f"user {m['user_s']:.2f} s, system {m['system_s']:.2f} s, "
                                                    f"{m['minor_faults']} minor faults" for m in main_thread))
    if not args.no_colmap:
        colmap = colmap_side(paths)
        if "error" in colmap:
            print(f"  COLMAP: {colmap['error']}")
        else:
            print(f"  COLMAP extraction {colmap['extract_cpu_s']:.2f} s CPU, matching and verification "
                  f"{colmap['match_cpu_s']:.2f} s CPU (every core); keypoints an image "
                  f"{np.mean(colmap['keypoints']):.0f}, verified pairs {colmap['verified_pairs']}")
    print(f"load {os.getloadavg()[0]:.1f} at end")
    return 0


if __name__ == "__main__":
    sys.exit(main())
