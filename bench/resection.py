"""Resection benchmark: every camera of the Oxford Dinosaur (from the points our certified
triangulation gives for the tracks it sees) and of the Oxford Model House (from its 3D points);
Oxford VGG data.

Prints per dataset, norm and rel_gap: median and p95 time and nodes over the cameras and how many
were certified; on a few 10-point subsets, SCIP and ours side by side (SCIP needs about 30 s even
for six points, so only --scip-cameras of each dataset); and the DLT + LM baseline per camera
(how often it is worse than the certified optimum, or puts a point at negative depth).

    .venv/bin/python -m bench.resection [--norms L2L2,L2L1,L1L1] [--gaps 1e-2,1e-3] [--scip-cameras 3]
                                        [--cameras N] [--time-limit S]
"""

from __future__ import annotations

import bench.one_blas_thread  # noqa: F401  (before numpy: one BLAS thread, as the workers have)

import argparse
import os
import pickle
import time
from pathlib import Path

import numpy as np

from geocert.solvers.datasets import load_dinosaur, load_house
from geocert.core.geometry import norm_cost
from bench.mapfits import apply
from geocert.solvers.fractional.maps import MapOptions, fit_map
from geocert.solvers.fractional.triangulation import NORMS, triangulate

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def dinosaur_problems() -> list[tuple[np.ndarray, np.ndarray]]:
    cameras, tracks = load_dinosaur(DATA / "oxford_dinosaur")
    per_camera: list[tuple[list, list]] = [([], []) for _ in cameras]
    for track in tracks:
        result = triangulate(cameras[track.views], track.points)
        if result.certified and not result.at_infinity:
            for view, pixel in zip(track.views, track.points):
                per_camera[view][0].append(result.point)
                per_camera[view][1].append(pixel)
    return [(np.array(s), np.array(t)) for s, t in per_camera]


def house_problems() -> list[tuple[np.ndarray, np.ndarray]]:
    _, points, views = load_house(DATA / "oxford_house")
    return [(points[v.point_indices], v.pixels) for v in views]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--norms", default=",".join(NORMS))
    parser.add_argument("--gaps", default="1e-2,1e-3")
    parser.add_argument("--scip-cameras", type=int, default=3)
    parser.add_argument("--time-limit", type=float, default=60.0, help="per camera, seconds")
    parser.add_argument("--cameras", type=int, default=0, help="evenly spaced cameras per dataset (0: all)")
    parser.add_argument("--problems", default="", help="a pickle of the problems: read when it exists, else "
                        "written (so that runs of two versions resect the same points)")
    args = parser.parse_args()
    if args.problems and Path(args.problems).exists():
        with open(args.problems, "rb") as f:
            datasets = pickle.load(f)
    else:
        datasets = {"Dinosaur": dinosaur_problems(), "House": house_problems()}
        if args.problems:
            with open(args.problems, "wb") as f:
                pickle.dump(datasets, f)
    if args.cameras:
        datasets = {name: [problems[i] for i in np.linspace(0, len(problems) - 1, args.cameras).astype(int)]
                    for name, problems in datasets.items()}
    print(f"load average {load()}; time limit {args.time_limit} s a camera")
    print(f"{'data':9} {'norm':5} {'gap':>6} {'cams':>4} {'points med':>10} {'median s':>9} {'p95 s':>7} "
          f"{'nodes med/p95':>14} {'certified':>9} {'CPU s med/p95':>14}  load")
    for name, problems in datasets.items():
        sizes = [len(s) for s, _ in problems]
        best_l2 = [np.inf] * len(problems)  # the best certified L2L2 cost seen per camera
        for norm in args.norms.split(","):
            for gap in (float(g) for g in args.gaps.split(",")):
                times, cpu, nodes, certified = fit_timed(problems, norm, gap, best_l2, args.time_limit)
                print(f"{name:9} {norm:5} {gap:6.0e} {len(problems):4d} {int(np.median(sizes)):10d} "
                      f"{np.median(times):9.2f} {np.percentile(times, 95):7.2f} "
                      f"{np.median(nodes):6.0f}/{np.percentile(nodes, 95):<7.0f} {certified:5d}/{len(problems)} "
                      f"{np.median(cpu):6.2f}/{np.percentile(cpu, 95):<7.2f}  {load()}", flush=True)
        if "L2L2" in args.norms.split(","):
            baseline(name, problems, best_l2)
        if args.scip_cameras:
            scip_subsets(name, problems, args.scip_cameras)


def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def fit_timed(problems, norm: str, gap: float, best_l2: list[float], time_limit: float):
    """bench.mapfits.fit_all with each camera's process (CPU) time beside its wall time."""
    times, cpu, nodes, certified = [], [], [], 0
    for index, (source, target) in enumerate(problems):
        start, start_cpu = time.perf_counter(), time.process_time()
        result = fit_map(source, target, MapOptions(norm=norm, rel_gap=gap, time_limit_s=time_limit))
        cpu.append(time.process_time() - start_cpu)
        times.append(time.perf_counter() - start)
        nodes.append(result.nodes)
        certified += result.certified
        if norm == "L2L2" and result.certified:
            best_l2[index] = min(best_l2[index], result.cost)
    return times, cpu, nodes, certified


def baseline(name: str, problems, certified_costs: list[float]) -> None:
    from testing.baselines import map_dlt_lm

    worse, negative, times = 0, 0, []
    for (source, target), optimum in zip(problems, certified_costs):
        start = time.perf_counter()
        M = map_dlt_lm(source, target)
        times.append(time.perf_counter() - start)
        depths = np.hstack([source, np.ones((len(source), 1))]) @ M[2]
        if not (np.all(depths > 0) or np.all(depths < 0)):
            negative += 1
            continue
        worse += norm_cost(apply(M, source) - target, "L2L2") > optimum * (1 + 1e-6)
    print(f"{name}: DLT + LM (L2L2) median {1e3 * np.median(times):.1f} ms per camera; costlier than our certified "
          f"map on {worse} of {len(problems)} cameras (uncertified cameras count as not); a point at negative "
          f"depth on {negative}")


def scip_subsets(name: str, problems, count: int) -> None:
    from testing.baselines import scip_map

    rng = np.random.default_rng(0)
    ours_t, scip_t, reached = [], [], 0
    for source, target in problems[:count]:
        pick = rng.choice(len(source), size=10, replace=False)
        s, t = source[pick], target[pick]
        start = time.perf_counter()
        fit_map(s, t, MapOptions(norm="L2L2", rel_gap=1e-2))
        ours_t.append(time.perf_counter() - start)
        start = time.perf_counter()
        _, ok, _, _ = scip_map(s, t, "L2L2", box=10.0, time_limit=120, gap=1e-2)
        scip_t.append(time.perf_counter() - start)
        reached += ok
    print(f"{name}: 10-point subsets of {count} cameras, L2L2, rel_gap 1e-2: ours median {1e3 * np.median(ours_t):.0f} ms, "
          f"SCIP median {1e3 * np.median(scip_t):.0f} ms (reached its gap {reached}/{count}, capped at 120 s): "
          f"{np.median(scip_t) / np.median(ours_t):.0f}x")


if __name__ == "__main__":
    main()
