"""The solvers' CPU against another revision's, in one run: the stratified autocalibration stages
at 20 views (Table 6.1's scenes, 0.1% noise, seeds 1 to 3, the bench's gaps) and bilinear
frames (N = 50, 0.5% noise, L2L2, K = 5 and 10 to certification, K = 20 for 10 s) and certified
resections (the Oxford Model House's 10 cameras from its 3D points, L2L2 at the gaps 1e-2, the
reconstruction's cameras', and 1e-3; needs ../shared/data) and 1000-point homographies (L1L1
and L2L2, gap 1e-3), each solved
by this checkout and by a copy of ``--against`` (``git archive``), in separate processes
alternating round by round, so that both see the same load. Prints per workload the median CPU
of each, their ratio, nodes and certified counts, and the load average at each round.

    .venv/bin/python -m bench.solver_revisions --against main [--rounds 3] [--only stratified|bilinear|resection|homography]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if __name__ == "__main__" and str(ROOT) not in sys.path:
    sys.path.append(str(ROOT))  # run as a script (the workers): bench importable, after the tree's geocert
BILINEAR = ((5, 0, 30.0), (5, 1, 30.0), (10, 0, 30.0), (10, 1, 30.0), (20, 0, 10.0))


def formulation(name: str):
    """A module of geocert/formulations, or of geocert/solvers in a revision from before the
    shared formulation had its own package (``--against`` may name one)."""
    import importlib

    try:
        return importlib.import_module(f"geocert.formulations.{name}")
    except ModuleNotFoundError:
        return importlib.import_module(f"geocert.solvers.{name}")


def stratified_rows() -> list[dict]:
    from geocert.solvers.autocalibration import affine, metric, scenes, stratified

    autocalibration_problem = formulation("autocalibration.problem")

    cpu: dict[str, float] = {}
    for module, name in ((affine, "solve_affine"), (metric, "solve_metric")):
        def timed(*args, _f=getattr(module, name), _key=name.split("_")[1], **kwargs):
            started = time.process_time()
            out = _f(*args, **kwargs)
            cpu[_key] = time.process_time() - started
            return out
        setattr(module, name, timed)
    rows = []
    for seed in (1, 2, 3):
        scene = scenes.make_scene(20, 0.1, seed=seed)
        problem = autocalibration_problem.prepare(scene.cameras, scene.points, scene.image_size, {})
        result = stratified.solve(problem, autocalibration_problem.AutocalibrationOptions(
            rel_gap=1e-5, metric_rel_gap=1e-4, time_limit_s=10))
        rows.append({"workload": "affine stage", "cpu": cpu["affine"], "nodes": result.affine.nodes,
                     "certified": bool(result.affine.certified), "status": result.affine.status})
        rows.append({"workload": "metric stage", "cpu": cpu["metric"], "nodes": result.metric.nodes,
                     "certified": bool(result.metric.certified), "status": result.metric.status})
    return rows


def bilinear_rows() -> list[dict]:
    from bench.bilinear import scene
    from geocert.solvers.bilinear.search import fit_frame

    BilinearOptions = formulation("bilinear.options").BilinearOptions

    rows = []
    for K, seed, limit in BILINEAR:
        basis, points, *_ = scene(K, 50, 0.005, seed)
        started = time.process_time()
        fit = fit_frame(basis, points, BilinearOptions(norm="L2L2", time_limit_s=limit))
        rows.append({"workload": f"bilinear K = {K}", "cpu": time.process_time() - started, "nodes": fit.nodes,
                     "certified": bool(fit.certified), "status": fit.status})
    return rows


def resection_rows() -> list[dict]:
    from geocert.solvers.datasets import load_house
    from geocert.solvers.fractional.maps import MapOptions, fit_map

    _, points, views = load_house(Path(os.environ.get("GEOCERT_SHARED_DATA", ROOT.parent / "shared" / "data"))
                                  / "oxford_house")
    problems = [(points[view.point_indices], view.pixels) for view in views]
    rows = []
    for gap in (1e-2, 1e-3):
        started, nodes, certified = time.process_time(), [], []
        for source, target in problems:
            result = fit_map(source, target, MapOptions(norm="L2L2", rel_gap=gap))
            nodes.append(result.nodes)
            certified.append(result.certified)
        rows.append({"workload": f"Model House's {len(problems)} resections, gap {gap:g}",
                     "cpu": time.process_time() - started, "nodes": sum(nodes), "certified": all(certified),
                     "status": "optimal" if all(certified) else f"{len(certified) - sum(certified)} not certified"})
    return rows


def homography_rows() -> list[dict]:
    """docs/benchmarks.md's L1L1 homography target: 1000 points, gap 1e-3 (bench.homography's planes)."""
    from bench.homography import instances
    from geocert.solvers.fractional.maps import MapOptions, fit_map

    rows = []
    for norm in ("L1L1", "L2L2"):
        for number, (source, target) in enumerate(instances(1000, 3, 1.0)):
            started = time.process_time()
            result = fit_map(source, target, MapOptions(norm=norm, rel_gap=1e-3))
            rows.append({"workload": f"{norm} homography, 1000 points, gap 1e-3", "cpu": time.process_time() - started,
                         "nodes": result.nodes, "certified": result.certified, "status": result.status})
    return rows


WORKLOADS = {"stratified": stratified_rows, "bilinear": bilinear_rows, "resection": resection_rows,
             "homography": homography_rows}


def measure(tree: Path, only: str) -> list[dict]:
    """One round of the workloads, solved by the code in ``tree`` (a fresh interpreter)."""
    env = {**os.environ, "PYTHONPATH": str(tree), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--worker", only, "--tree", str(tree)],
                         cwd=tree, env=env, capture_output=True, text=True, check=True, timeout=1800)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", default="main", help="the revision to compare with (git)")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--only", choices=(*WORKLOADS, "all"), default="all")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    parser.add_argument("--tree", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        import geocert

        # the tree's own code, not the checkout installed in the environment
        assert Path(geocert.__file__).resolve().is_relative_to(Path(args.tree).resolve()), geocert.__file__
        rows = [row for name, workload in WORKLOADS.items() if args.worker in (name, "all") for row in workload()]
        print(json.dumps(rows))
        return
    with tempfile.TemporaryDirectory() as other:
        archive = subprocess.run(["git", "archive", args.against, "geocert", "bench"], cwd=ROOT, capture_output=True,
                                 check=True).stdout
        subprocess.run(["tar", "-x", "-C", other], input=archive, check=True)
        trees = {f"{args.against}": Path(other), "this checkout": ROOT}
        results: dict[tuple[str, str], list[dict]] = {}
        for number in range(args.rounds):
            for name, tree in trees.items():
                load = os.getloadavg()[0]
                for row in measure(tree, args.only):
                    results.setdefault((name, row["workload"]), []).append(row)
                print(f"round {number + 1}, {name}: load average {load:.1f}", flush=True)
    before, after = trees
    print(f"\n| workload | {before}: median CPU s | this checkout | ratio | nodes (median, {before} / this) | "
          "certified | not certified: why |")
    print("|---|---|---|---|---|---|---|")
    for workload in dict.fromkeys(w for _, w in results):
        a, b = results[before, workload], results[after, workload]
        ma, mb = statistics.median(r["cpu"] for r in a), statistics.median(r["cpu"] for r in b)
        na, nb = statistics.median(r["nodes"] for r in a), statistics.median(r["nodes"] for r in b)
        print(f"| {workload} | {ma:.3f} | {mb:.3f} | {mb / ma:.2f} | {na:g} / {nb:g} | "
              f"{sum(r['certified'] for r in a)}/{len(a)}, {sum(r['certified'] for r in b)}/{len(b)} | "
              f"{', '.join(sorted({r['status'] for r in a + b if not r['certified']})) or '-'} |")


if __name__ == "__main__":
    main()
