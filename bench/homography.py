"""2D homography benchmark: certified fits from 4, 10, 100 and 1000 correspondences.

Synthetic planes seen by a 640x480 camera (800 px focal length) from random viewpoints, with
Gaussian pixel noise. Prints per size, norm and rel_gap: median and p95 time and nodes, how many
were certified; and, side by side, OpenCV's ``findHomography`` (method 0: least squares on all
points, then Levenberg-Marquardt) with how often its L2L2 cost exceeds our certified one.

    .venv/bin/python -m bench.homography [--sizes 4,10,100,1000] [--norms L2L2,L2L1,L1L1]
                                         [--gaps 1e-2,1e-3] [--instances 10] [--noise 1.0]
"""

from __future__ import annotations

import bench.one_blas_thread  # noqa: F401  (before numpy: one BLAS thread, as the workers have)

import argparse
import os
import time

import cv2
import numpy as np

from geocert.core.geometry import norm_cost
from bench.mapfits import apply, fit_all
from geocert.solvers.fractional.triangulation import NORMS


def plane_homography(rng: np.random.Generator) -> np.ndarray:
    """H = K [r1 r2 t]: the plane z = 0 seen from about 8 units away."""
    centre = rng.normal(size=3) * 2 + np.array([0.0, 0.0, -8.0])
    z = rng.normal(size=3) * 0.3 - centre
    z /= np.linalg.norm(z)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    K = np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]])
    P = K @ np.hstack([R, -R @ centre[:, None]])
    return P[:, [0, 1, 3]]


def instances(size: int, count: int, noise: float, seed: int = 0):
    rng = np.random.default_rng(seed + size)
    for _ in range(count):
        H = plane_homography(rng)
        source = rng.uniform(-2, 2, size=(size, 2))
        yield source, apply(H, source) + rng.normal(size=(size, 2)) * noise


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", default="4,10,100,1000")
    parser.add_argument("--norms", default=",".join(NORMS))
    parser.add_argument("--gaps", default="1e-2,1e-3")
    parser.add_argument("--instances", type=int, default=10)
    parser.add_argument("--noise", type=float, default=1.0, help="pixels")
    args = parser.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"{'points':>6} {'norm':5} {'gap':>6} {'median ms':>10} {'p95 ms':>8} {'nodes med/p95':>14} {'certified':>9} "
          f"{'CPU ms med/p95':>15}")
    for size in sizes:
        problems = list(instances(size, args.instances, args.noise))
        best_l2 = [np.inf] * len(problems)
        for norm in args.norms.split(","):
            for gap in (float(g) for g in args.gaps.split(",")):
                times, nodes, certified, cpu = fit_all(problems, norm, gap, best_l2)
                print(f"{size:6d} {norm:5} {gap:6.0e} {1e3 * np.median(times):10.1f} {1e3 * np.percentile(times, 95):8.1f} "
                      f"{np.median(nodes):6.0f}/{np.percentile(nodes, 95):<7.0f} {certified:5d}/{len(problems)} "
                      f"{1e3 * np.median(cpu):7.1f}/{1e3 * np.percentile(cpu, 95):<7.1f}", flush=True)
        if "L2L2" in args.norms.split(","):
            opencv_baseline(size, problems, best_l2)


def opencv_baseline(size: int, problems, certified_costs: list[float]) -> None:
    times, worse = [], 0
    for (source, target), optimum in zip(problems, certified_costs):
        start = time.perf_counter()
        H, _ = cv2.findHomography(source, target, 0)
        times.append(time.perf_counter() - start)
        worse += H is None or norm_cost(apply(H, source) - target, "L2L2") > optimum * (1 + 1e-6) + 1e-9
    print(f"{size:6d} findHomography (method 0) median {1e3 * np.median(times):.2f} ms; L2L2 cost above our certified "
          f"optimum on {worse} of {len(problems)}")


if __name__ == "__main__":
    main()
