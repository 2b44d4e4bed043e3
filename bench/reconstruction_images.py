"""Image stage and K-known reconstruction (issue 14): photos -> tracks -> cameras, against truth.

Datasets: Middlebury dinoSparseRing (Seitz, Curless, Diebel, Scharstein and Szeliski, CVPR 2006;
14 photos 640x480 of an untextured object, ground-truth K, R, t) with the tuned options the test
uses, and a synthetic render (a textured box on a textured ground, 8 views over 150 degrees,
geocert.solvers.reconstruction.render). Prints per dataset: features per image, verified pairs,
tracks, views registered, rotation error after aligning to the truth (median / max degrees),
RMS reprojection error and time per step.

    .venv/bin/python -m bench.reconstruction_images [--no-ring] [--no-render] [--merge]
"""

from __future__ import annotations

import os

# One BLAS thread: the stages are single-threaded, and OpenBLAS's spinning threads on this shared
# 2-core machine cost more than they gain (measured: a 432 x 432 Cholesky 150 ms of CPU with the
# default threads under load, the Dinosaur's projective stage 25.5 s CPU against 13.2 s with one).
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import time
from pathlib import Path

import cv2
import numpy as np

from bench import machine_speed_ms
from geocert.solvers.reconstruction.calibrated import (CalibratedOptions, align_rotations,
                                                       calibrated_reconstruction)
from geocert.solvers.reconstruction.features import FeatureOptions, tracks_from_images
from geocert.solvers.reconstruction.render import box_scene

RING = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "middlebury_dinoSparseRing"
# The options the ring needs (tests/solvers/test_reconstruction_images.py uses the same).
RING_FEATURES = FeatureOptions(max_features=0, contrast_threshold=0.005, ratio=0.85, ransac_threshold_px=2.0)
RING_CALIBRATED = CalibratedOptions(pnp_min_inliers=10)


def load_ring():
    rows = [line.split() for line in (RING / "dinoSR_par.txt").read_text().splitlines()[1:] if line.strip()]
    values = [np.array(r[1:], dtype=float) for r in rows]
    images = [cv2.imread(str(RING / r[0]), cv2.IMREAD_GRAYSCALE) for r in rows]
    return [r[0] for r in rows], images, [v[:9].reshape(3, 3) for v in values], [v[9:18].reshape(3, 3) for v in values]


def print_per_view(names, tracks_stats, per_view, errors, reasons):
    """One line per view: where it stands at each stage. Features (SIFT keypoints); the views it
    has a verified pair with (inliers); tracks through it; linked: those tracks also observed (as
    inliers) by another, registered view; points: those with a triangulated point it observes
    (what PnP works from); then the rotation error, or the reason it is not registered."""
    partners = {v: [] for v in range(len(per_view))}
    for pair in tracks_stats["verified_pairs"]:
        i, j = pair["views"]
        partners[i].append(f"{j}:{pair['inliers']}")
        partners[j].append(f"{i}:{pair['inliers']}")
    print(f"  {'view':<18} {'features':>8} {'tracks':>6} {'linked':>6} {'points':>6}  outcome / verified pairs (view:inliers)")
    for v, figures in enumerate(per_view):
        label = f"{v} {names[v]}" if names else str(v)
        outcome = (f"{errors[v]:.2f} deg ({figures['registered_by']})" if v in errors else f"unregistered: {reasons[v]}")
        print(f"  {label:<18} {tracks_stats['features_per_image'][v]:>8} {figures['tracks']:>6} {figures['linked']:>6} "
              f"{figures['points']:>6}  {outcome}\n  {'':<18} {'':>8} {'':>6} {'':>6} {'':>6}  pairs {' '.join(partners[v]) or '-'}")


def run(name, images, Ks, Rs, feature_options, calibrated_options, names=None):
    start = time.perf_counter()
    tracks = tracks_from_images(images, feature_options)
    tracks_s = time.perf_counter() - start
    start = time.perf_counter()
    result = calibrated_reconstruction(tracks.tracks, Ks, calibrated_options)
    recon_s = time.perf_counter() - start
    registered = [v for v in range(len(images)) if result.rotations[v] is not None]
    _, errors = align_rotations([result.rotations[v] for v in registered], [Rs[v] for v in registered])
    s, c = tracks.stats, result.stats
    print(f"\n== {name}: {len(images)} images")
    print(f"features per image   {s['features_per_image']}")
    print(f"pairs                {s['candidate_pairs']} matched, {len(s['verified_pairs'])} verified "
          f"(inliers {sorted(p['inliers'] for p in s['verified_pairs'])})")
    print(f"tracks               {s['tracks_built']} built, {s['dropped_inconsistent']} inconsistent dropped, "
          f"{s['tracks_kept']} kept")
    print(f"views registered     {c['registered']} / {len(images)}   initial pair {c.get('initial_pair')}")
    print(f"points               {c['points']}   outlier observations removed {c['outliers_removed']}   "
          f"RMS reprojection {c['rms_reprojection_px']:.3f} px   BA evaluations {c['ba_iterations']}")
    if registered:
        print(f"rotation error deg   median {np.median(errors):.3f}   max {errors.max():.3f}   "
              f"within 1 deg: {int(np.sum(errors < 1.0))} / {len(images)}")
        print("  per view           " + "  ".join(f"{v}:{e:.2f}" for v, e in zip(registered, errors)))
    print_per_view(names, s, c["per_view"], dict(zip(registered, errors)), result.reasons)
    times = {**{f"tracks.{k}": t for k, t in s["time_s"].items()}, **{f"recon.{k}": t for k, t in c["time_s"].items()}}
    print("time s               " + "  ".join(f"{k} {t:.2f}" for k, t in times.items())
          + f"   (total tracks {tracks_s:.1f}, reconstruction {recon_s:.1f})")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-ring", action="store_true")
    parser.add_argument("--no-render", action="store_true")
    parser.add_argument("--merge", action="store_true", help="the ring again with merge_components=True")
    args = parser.parse_args()
    print(f"machine speed: {machine_speed_ms():.0f} ms for the reference loop (shared machine: timings inflated)")
    if not args.no_ring:
        if RING.exists():
            names, images, Ks, Rs = load_ring()
            run("Middlebury dinoSparseRing (K given)", images, Ks, Rs, RING_FEATURES, RING_CALIBRATED, names)
            if args.merge:
                run("Middlebury dinoSparseRing (K given, merge_components=True)", images, Ks, Rs, RING_FEATURES,
                    CalibratedOptions(pnp_min_inliers=10, merge_components=True), names)
        else:
            print(f"{RING} not found: ring skipped")
    if not args.no_render:
        scene = box_scene(n_views=8, arc_deg=150.0, seed=0)
        run("synthetic render (textured box, K given)", scene.images(), [c.K for c in scene.cameras],
            [c.R for c in scene.cameras], FeatureOptions(), CalibratedOptions())


if __name__ == "__main__":
    main()
