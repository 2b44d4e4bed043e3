"""Bilinear fitting benchmark (thesis 8.5.1, in miniature): synthetic exemplar scenes with noise and
outliers, the certified L1 and L2 fits beside the linear baseline (regression then SVD); RMS
reprojection error, 3D shape error, camera and coefficient errors, nodes, time and certified
fraction; SCIP on a few small instances.

    .venv/bin/python -m bench.bilinear [--trials 5] [--quick]
"""

from __future__ import annotations

import bench.one_blas_thread  # noqa: F401  (before numpy: one BLAS thread, as the workers have)

import argparse
import math
import os
import time

import numpy as np

from geocert.formulations.bilinear import problem as bilinear_problem
from geocert.formulations.bilinear.options import BilinearOptions
from geocert.solvers.bilinear.search import fit_frame
from testing.bilinear import scene, scip_bilinear


def errors(basis, clean, camera, alpha, true_camera, true_alpha) -> dict:
    """The thesis's error measures (8.5.1): RMS reprojection error against the noiseless image,
    camera error relative to the true camera's norm, coefficient error, RMS 3D error."""
    S, S_true = bilinear_problem.shape_of(basis, alpha), bilinear_problem.shape_of(basis, true_alpha)
    image = bilinear_problem.shape_of(basis, alpha) @ camera[:, :3].T + camera[:, 3]
    return {"reprojection": float(np.sqrt(np.mean(np.sum((image - clean) ** 2, axis=1)))),
            "camera": float(np.linalg.norm(camera - true_camera) / np.linalg.norm(true_camera)),
            "coefficients": float(np.sqrt(np.mean((alpha - true_alpha) ** 2))),
            "shape": float(np.sqrt(np.mean(np.sum((S - S_true) ** 2, axis=1))))}


TIME_LIMIT = 30.0


def nonrigid(frames: int = 240, points: int = 91, noise: float = 0.002, seed: int = 5,
             service_workers: int = 0) -> None:
    """A synthetic deforming object (thesis 8.5.2's shark protocol in kind: 240 frames of 91 points,
    two basis shapes, varying camera orientation): each frame's shape is (1 - w) S0 + w S1 with w
    oscillating in [-0.4, 1.4] (affine coefficients), seen by a scaled orthographic camera of
    varying orientation, with Gaussian noise; all frames solved as one job in-process
    (geocert.jobs.runner.solve_job, one item per frame). Prints the mean 3D shape error (RMS over points,
    relative to the shape's RMS size) and frames per second."""
    from geocert.jobs.runner import solve_job

    rng = np.random.default_rng(seed)
    s = np.linspace(0, 1, points)
    body = np.column_stack([4 * s - 2, 0.4 * np.sin(np.pi * s) * rng.uniform(0.8, 1.2, points),
                            0.5 * np.cos(3 * np.pi * s) * rng.uniform(0.8, 1.2, points)])
    bend = np.column_stack([np.zeros(points), 0.8 * (s - 0.5) ** 2, 1.2 * np.sin(2 * np.pi * s) * s])
    basis = np.array([body, body + bend])
    data, truth = [], []
    size = 200.0
    for f in range(frames):
        w = 0.5 + 0.9 * math.sin(2 * math.pi * f / 60)
        alpha = np.array([1 - w, w])
        angle, tilt = 2 * math.pi * f / frames, 0.4 * math.sin(2 * math.pi * f / 80)
        R = _rotation(angle, tilt)
        camera = np.hstack([50 * R[:2], rng.uniform(-20, 20, (2, 1))])
        S = bilinear_problem.shape_of(basis, alpha)
        image = S @ camera[:, :3].T + camera[:, 3] + rng.normal(size=(points, 2)) * noise * size
        data.append({"points": image.tolist()})
        truth.append(S)
    job = {"kind": "bilinear", "data": {"basis": basis.tolist(), "frames": data},
           "options": {"norm": "L2L2", "coefficients": "affine"}}
    if service_workers:
        result, elapsed = through_service(job, service_workers)
        where = f"through the service, {service_workers} workers"
    else:
        start = time.perf_counter()
        result = solve_job(job)
        elapsed = time.perf_counter() - start
        where = "in-process, 1 core"
    errors_ = []
    for item, S in zip(result["frames"], truth):
        fitted = np.array(item["shape"])
        errors_.append(np.sqrt(np.mean(np.sum((fitted - S) ** 2, axis=1))) / np.sqrt(np.mean(np.sum(
            (S - S.mean(axis=0)) ** 2, axis=1))))
    certified = sum(item["certified"] for item in result["frames"])
    nodes = [item["nodes"] for item in result["frames"]]
    print(f"\nnon-rigid sequence: {frames} frames, {points} points, 2 basis shapes, affine coefficients, "
          f"{noise:.1%} noise, L2L2")
    print(f"| mean 3D shape error | max | certified | nodes med/max | frames/s ({where}) |")
    print("|---|---|---|---|---|")
    print(f"| {np.mean(errors_):.2%} | {np.max(errors_):.2%} | {certified}/{frames} | "
          f"{np.median(nodes):.0f}/{max(nodes)} | {frames / elapsed:.1f} |", flush=True)


def through_service(job: dict, workers: int) -> tuple[dict, float]:
    """The job through a real service (Redis, the API, ``workers`` worker processes): its result
    and the seconds from submit to the finished document."""
    from bench.faults import cluster, wait_end

    with cluster(workers=workers) as running:
        warm = {**job, "data": {**job["data"], "frames": job["data"]["frames"][:2]}}
        wait_end(running.client, running.client.post("/v1/jobs", json=warm).json()["id"])
        start = time.perf_counter()
        response = running.client.post("/v1/jobs", json=job)
        response.raise_for_status()
        document = wait_end(running.client, response.json()["id"], limit_s=3600)
        return document["result"], time.perf_counter() - start


def gap_anatomy(K: int = 20, N: int = 50, seed: int = 0) -> None:
    """Why the gap stalls at large K: one frame's relaxation on the root box after tightening
    (half-width ``h`` about the incumbent for the camera, the coefficients' box tightened for it),
    then the same with one side's box shrunk about the incumbent (scaled by f) or pinned at it.
    McCormick's error is the product of the camera's and the coefficients' widths: shrinking
    either by f shrinks the gap by about f, and pinning either closes it."""
    from geocert.formulations.bilinear.relaxation import Relaxation
    from geocert.solvers.bilinear.search import Model, root_incumbent, tighten
    from geocert.core.conic import ReusableConicProgram

    basis, points, *_ = scene(K, N, 0.005, seed)
    frame = bilinear_problem.normalise(basis, points)
    model = Model(frame, "L2L2", "convex", 10.0)
    M0, a0, _, value = root_incumbent(model)
    relaxation = Relaxation(frame.X, frame.u, "L2L2", "convex", 10.0)
    solver = ReusableConicProgram(lean=False)
    cap = value * (1 + 1e-9)
    M0 = M0.ravel()

    def gap(lo, hi, alo, ahi) -> float:
        data = relaxation.conic_data(lo, hi, cap, alo, ahi)
        res = solver.solve(data.q, data.A, data.b, data.cones)
        return 1 - relaxation.bound(data, res.z) / value

    print(f"\nwhy the gap stalls: K = {K}, N = {N}, 0.5% noise, L2L2, one frame; relative gap of the relaxation "
          "about the incumbent, the coefficients' box tightened for the camera box (cost at most the incumbent's)")
    print("| camera box half-width | tightened camera width | coefficient widths (sum) | gap | camera box x0.5 | "
          "x0.1 | pinned | coefficient box x0.5 | x0.1 | pinned |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for h in (0.5, 0.05, 0.02):
        lo, hi, alo, ahi, _ = tighten(relaxation, M0 - h, M0 + h, cap)
        cells = []
        for f in (0.5, 0.1, 0.0):
            cells.append(gap(M0 - f * (M0 - lo), M0 + f * (hi - M0), alo, ahi))
        for f in (0.5, 0.1, 0.0):
            cells.append(gap(lo, hi, np.maximum(alo, a0 - f * (a0 - alo)), np.minimum(ahi, a0 + f * (ahi - a0))))
        print(f"| {h:g} | {np.max(hi - lo):.3g} | {np.sum(ahi - alo):.3g} | {gap(lo, hi, alo, ahi):.2%} | "
              + " | ".join(f"{c:.2%}" for c in cells) + " |", flush=True)


def relaxation_capacity(N: int = 50, seed: int = 0, widths=(0.1, 0.01, 0.001)) -> None:
    """Why K = 20 and 40 with N = 50 points do not certify: one frame per K, the root relaxation's
    relative gap on camera boxes of half-width h about the incumbent (normalised units; the
    coefficients' box tightened for each), beside the count that decides it. The relaxation's
    prediction of the 2N image coordinates is linear in its 6K lifted products gamma and the
    translation (2), tied to M by 6 exact RLT rows: 6K - 4 free directions against 2N
    coordinates. Once 6K - 4 >= 2N (K >= 18 at N = 50) the lifted model fits any image exactly
    and only McCormick's envelopes keep the bound above 0; their slack is the product of the
    camera's and the coefficients' widths, so the gap falls only as the 6-dimensional camera box
    shrinks (boxes needed grow as (1/h)^6)."""
    from geocert.solvers.bilinear.search import tighten
    from geocert.core.conic import ReusableConicProgram

    print(f"\nrelaxation capacity: N = {N}, 0.5% noise, L2L2, one frame per K; the root relaxation's relative gap "
          "on a camera box of half-width h about the incumbent (coefficients tightened for it); CPU s of the "
          "tightening and solve per box")
    print("| K | 6K - 4 | 2N | " + " | ".join(f"gap, h = {h:g}" for h in widths) + " | CPU s per box |")
    print("|---|---|---|" + "---|" * len(widths) + "---|")
    for K in (5, 10, 15, 17, 18, 20, 40):
        _, relaxation, M0, value = _at_incumbent(K, N, seed)
        solver = ReusableConicProgram(lean=False)
        cap = value * (1 + 1e-9)
        cells, cpu = [], []
        for h in widths:
            started = time.process_time()
            lo, hi, alo, ahi, _ = tighten(relaxation, M0 - h, M0 + h, cap)
            data = relaxation.conic_data(lo, hi, cap, alo, ahi)
            res = solver.solve(data.q, data.A, data.b, data.cones)
            cells.append(1 - relaxation.bound(data, res.z) / value)
            cpu.append(time.process_time() - started)
        print(f"| {K} | {6 * K - 4} | {2 * N} | " + " | ".join(f"{c:.2%}" for c in cells)
              + f" | {np.median(cpu):.2f} |", flush=True)


def trajectory(N: int = 50, seed: int = 0, runs=((20, 10.0), (40, 60.0)), widths=(0.01, 0.003, 0.001)) -> None:
    """Issue 38: where K = 20 and 40 stand against the targets (certified at the 1e-3 gap within
    10 s and 60 s a frame). Per K: the frame solved by fit_frame within its target's limit, its
    gap over processor time (nodes, open boxes, lower bound, incumbent), the CPU per node; then
    the root relaxation's gap at a few box half-widths h about the incumbent, the exponent p of
    gap ~ h^p between the last two, the half-width h* where the gap would reach 1e-3, and the
    boxes of half-width h* it takes to cover the box of the first h about the incumbent (where the
    bound is near the optimum: boxes there prune only at h*) and the root's camera box, in 6
    dimensions, times the measured CPU per box: the search the relaxation asks for."""
    from geocert.solvers.bilinear.search import tighten
    from geocert.core.conic import ReusableConicProgram

    print(f"\ngap over time: N = {N}, 0.5% noise, L2L2, convex coefficients, seed {seed}; "
          f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
    for K, limit in runs:
        basis, points, *_ = scene(K, N, 0.005, seed)
        rows = []
        began = time.process_time()

        def record(progress, began=began, rows=rows):
            rows.append((time.process_time() - began, progress.nodes, progress.open_boxes, progress.lower_bound,
                         progress.upper_bound, progress.gap_rel))

        result = fit_frame(basis, points, BilinearOptions(norm="L2L2", time_limit_s=limit, max_nodes=100000), record)
        cpu = time.process_time() - began
        print(f"K = {K}, time limit {limit:g} s: {result.status}, {result.nodes} nodes, {cpu:.1f} s of CPU "
              f"({cpu / max(result.nodes, 1):.2f} s a node), certified {result.certified}")
        print("| CPU s | nodes | open boxes | lower bound | incumbent | relative gap |")
        print("|---|---|---|---|---|---|")
        shown = rows if len(rows) <= 12 else [rows[int(i)] for i in np.linspace(0, len(rows) - 1, 12)]
        for t, nodes, open_, lower, upper, gap in shown:
            print(f"| {t:.1f} | {nodes} | {open_} | {lower:.4g} | {upper:.4g} | {gap:.2%} |")
        frame, relaxation, M0, value = _at_incumbent(K, N, seed)
        root = bilinear_problem.default_half_width(M0.reshape(2, 3))
        solver = ReusableConicProgram(lean=False)
        gaps, box_cpu = [], []
        for h in widths:
            started = time.process_time()
            lo, hi, alo, ahi, _ = tighten(relaxation, M0 - h, M0 + h, value * (1 + 1e-9))
            data = relaxation.conic_data(lo, hi, value * (1 + 1e-9), alo, ahi)
            res = solver.solve(data.q, data.A, data.b, data.cones)
            gaps.append(max(1 - relaxation.bound(data, res.z) / value, 1e-12))
            box_cpu.append(time.process_time() - started)
        p = math.log(gaps[-2] / gaps[-1]) / math.log(widths[-2] / widths[-1])
        h_star = widths[-1] * (1e-3 / gaps[-1]) ** (1 / p)
        boxes, near = (root / h_star) ** 6, (widths[0] / h_star) ** 6
        each = float(np.median(box_cpu))
        print("root gap by box half-width h about the incumbent: "
              + ", ".join(f"h = {h:g}: {g:.3%}" for h, g in zip(widths, gaps))
              + f"; gap ~ h^{p:.2f}, 1e-3 at h* = {h_star:.2g}; {each:.2f} s of CPU a box")
        print(f"  boxes of half-width h* covering the h = {widths[0]:g} box about the incumbent: {near:.2g} "
              f"({near * each:.2g} s); covering the root box (half-width {root:.3g}): {boxes:.2g} "
              f"({boxes * each:.2g} s)")


def _at_incumbent(K: int, N: int, seed: int):
    """One frame (0.5% noise) in normalised units, its L2L2 relaxation (convex coefficients), the
    root incumbent's camera (6 entries) and cost."""
    from geocert.formulations.bilinear.relaxation import Relaxation
    from geocert.solvers.bilinear.search import Model, root_incumbent

    basis, points, *_ = scene(K, N, 0.005, seed)
    frame = bilinear_problem.normalise(basis, points)
    M0, _, _, value = root_incumbent(Model(frame, "L2L2", "convex", 10.0))
    return frame, Relaxation(frame.X, frame.u, "L2L2", "convex", 10.0), M0.ravel(), value


def shor_capacity(N: int = 50, seed: int = 0, widths=(0.1, 0.01)) -> None:
    """What a tighter relaxation would give: on the boxes of relaxation_capacity (half-width h
    about the incumbent, the coefficients' box tightened for it), the root gap of the McCormick
    relaxation the search uses beside the same relaxation with Shor's semidefinite constraint
    added: the moment matrix of (1, m, alpha) (size 7 + K) positive semidefinite, its (m, alpha)
    block the lifted products gamma, its other blocks tied by McCormick's (and, for convex
    coefficients, the simplex's) product rows. Solved with cvxpy and Clarabel (the test extra's
    cvxpy), not safe bounds: a measurement of the relaxation's strength, not a certificate."""
    import cvxpy as cp

    from geocert.solvers.bilinear.search import tighten
    from geocert.core.conic import ReusableConicProgram

    print(f"\nShor's relaxation against McCormick's: N = {N}, 0.5% noise, L2L2, one frame per K; the root gap on a "
          "camera box of half-width h about the incumbent (coefficients tightened for it), and the CPU s of one "
          "solve of each")
    print("| K | h | McCormick gap | Shor + McCormick gap | McCormick s | Shor s |")
    print("|---|---|---|---|---|---|")
    for K in (5, 10, 20, 40):
        frame, relaxation, M0, value = _at_incumbent(K, N, seed)
        solver = ReusableConicProgram(lean=False)
        cap = value * (1 + 1e-9)
        for h in widths:
            lo, hi, alo, ahi, _ = tighten(relaxation, M0 - h, M0 + h, cap)
            started = time.process_time()
            data = relaxation.conic_data(lo, hi, cap, alo, ahi)
            res = solver.solve(data.q, data.A, data.b, data.cones)
            mccormick = 1 - relaxation.bound(data, res.z) / value
            mccormick_s = time.process_time() - started
            started = time.process_time()
            shor = _shor_bound(cp, frame.X, frame.u, lo, hi, alo, ahi)
            shor_s = time.process_time() - started
            print(f"| {K} | {h:g} | {mccormick:.2%} | {1 - shor / value:.2%} | {mccormick_s:.2f} | {shor_s:.2f} |",
                  flush=True)


def _shor_bound(cp, X: np.ndarray, u: np.ndarray, lo, hi, alo, ahi) -> float:
    """min sum of squared residuals over the McCormick relaxation with Shor's PSD moment matrix
    (convex coefficients), in normalised units."""
    K, n, _ = X.shape
    d = 7 + K
    Y = cp.Variable((d, d), symmetric=True)
    m, a = Y[0, 1:7], Y[0, 7:]
    G = Y[1:7, 7:]  # gamma_{rk, i} = M_rk alpha_i
    MM, AA = Y[1:7, 1:7], Y[7:, 7:]
    t = cp.Variable(2)
    lo, hi, alo, ahi = (np.asarray(v, float) for v in (lo, hi, alo, ahi))
    cons = [Y >> 0, Y[0, 0] == 1, cp.sum(a) == 1, cp.sum(G, axis=1) == m, cp.sum(AA, axis=1) == a,
            m >= lo, m <= hi, a >= alo, a <= ahi]
    for P, x, xl, xu, y, yl, yu in ((G, m, lo, hi, a, alo, ahi), (MM, m, lo, hi, m, lo, hi),
                                    (AA, a, alo, ahi, a, alo, ahi)):
        X1, Y1 = cp.reshape(x, (len(xl), 1), order="F"), cp.reshape(y, (1, len(yl)), order="F")
        cons += [P >= X1 @ yl[None, :] + xl[:, None] @ Y1 - np.outer(xl, yl),
                 P >= X1 @ yu[None, :] + xu[:, None] @ Y1 - np.outer(xu, yu),
                 P <= X1 @ yu[None, :] + xl[:, None] @ Y1 - np.outer(xl, yu),
                 P <= X1 @ yl[None, :] + xu[:, None] @ Y1 - np.outer(xu, yl)]
    prediction = []
    for r in range(2):
        # sum_k sum_i X[i, j, k] gamma_{3r + k, i} + t_r, for every point j
        prediction.append(sum(X[:, :, k].T @ G[3 * r + k, :] for k in range(3)) + t[r])
    residual = cp.hstack([u[:, 0] - prediction[0], u[:, 1] - prediction[1]])
    problem = cp.Problem(cp.Minimize(cp.sum_squares(residual)), cons)
    problem.solve(solver=cp.CLARABEL)
    return float(problem.value)


def _rotation(angle: float, tilt: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    yaw = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    c, s = math.cos(tilt), math.sin(tilt)
    pitch = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    return pitch @ yaw


def run(trials: int, quick: bool) -> None:
    started = time.perf_counter()
    rows = []
    settings = [(5, 0.005, 0.0), (10, 0.005, 0.0), (20, 0.005, 0.0), (40, 0.005, 0.0),
                (10, 0.001, 0.0), (10, 0.01, 0.0), (10, 0.005, 0.1), (10, 0.005, 0.3)]
    if quick:
        settings = settings[:2]
    N = 50
    print(f"bilinear fitting, N = {N} points, {trials} trials per row, time limit {TIME_LIMIT:g} s per frame, "
          "rel_gap 1e-3; noise in % of the image size (200 units), outliers moved by 10% of it")
    print("| K | noise | outliers | method | RMS reproj. | 3D error | camera err. | coeff. err. | nodes med | "
          "time med s | time max s | certified |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for K, noise, outliers in settings:
        results: dict[str, list] = {"L1L1": [], "L2L2": [], "linear": []}
        for seed in range(trials):
            basis, points, camera, alpha, clean = scene(K, N, noise, seed, outliers)
            for norm in ("L1L1", "L2L2"):
                start = time.perf_counter()
                fit = fit_frame(basis, points, BilinearOptions(norm=norm, time_limit_s=TIME_LIMIT))
                elapsed = time.perf_counter() - start
                e = errors(basis, clean, np.array(fit.camera), np.array(fit.coefficients), camera, alpha)
                results[norm].append({**e, "nodes": fit.nodes, "time": elapsed, "certified": fit.certified})
                if norm == "L2L2":
                    b = fit.baseline
                    e = errors(basis, clean, np.array(b["camera"]), np.array(b["coefficients"]), camera, alpha)
                    results["linear"].append({**e, "nodes": 0, "time": 0.0, "certified": False})
        for method, entries in results.items():
            def med(key):
                return float(np.median([x[key] for x in entries]))
            certified = sum(x["certified"] for x in entries)
            timing = (f"{med('nodes'):.0f} | {med('time'):.2f} | {max(x['time'] for x in entries):.2f} | "
                      f"{certified}/{len(entries)}") if method != "linear" else "- | - | - | -"
            print(f"| {K} | {noise:.1%} | {outliers:.0%} | {method} | {med('reprojection'):.3f} | {med('shape'):.4f} | "
                  f"{med('camera'):.4f} | {med('coefficients'):.4f} | {timing} |", flush=True)
            rows.append((K, noise, outliers, method, entries))
    gap_anatomy()
    nonrigid(60 if quick else 240)
    print("\nSCIP on small instances (K = 3, N = 8, 0.5% noise; the same camera box, rel. gap 1e-7, 60 s)")
    print("| seed | norm | ours cost | ours lower | ours s | SCIP cost | SCIP dual | SCIP s | SCIP inside [lower, cost] |")
    print("|---|---|---|---|---|---|---|---|---|")
    for seed in range(2 if quick else 3):
        basis, points, *_ = scene(3, 8, 0.005, 100 + seed)
        for norm in ("L1L1", "L2L2"):
            start = time.perf_counter()
            fit = fit_frame(basis, points, BilinearOptions(norm=norm, rel_gap=1e-6, abs_gap=1e-9))
            ours = time.perf_counter() - start
            bound = fit.camera_box[1][0] if fit.camera_box else 4 * float(np.abs(np.array(fit.camera)[:, :3]).max())
            start = time.perf_counter()
            cost, dual, done = scip_bilinear(basis, points, norm, bound, time_limit=60)
            scip = time.perf_counter() - start
            inside = fit.lower_bound - 1e-6 * abs(fit.cost) <= cost <= fit.cost + 1e-6 * abs(fit.cost)
            print(f"| {seed} | {norm} | {fit.cost:.6g} | {fit.lower_bound:.6g} | {ours:.2f} | {cost:.6g} | {dual:.6g} | "
                  f"{scip:.2f}{'' if done else ' (limit)'} | {inside} |", flush=True)
    print(f"\ntotal {time.perf_counter() - started:.0f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=5)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--capacity", action="store_true", help="only the relaxation's capacity table")
    parser.add_argument("--trajectory", action="store_true",
                        help="issue 38: K = 20 (10 s) and 40 (60 s): the gap over time, CPU per node, "
                        "the boxes the relaxation asks for")
    parser.add_argument("--shor", action="store_true",
                        help="only the root gap with Shor's semidefinite constraint added (needs cvxpy, the test extra)")
    parser.add_argument("--nonrigid-service", type=int, default=0, metavar="WORKERS",
                        help="only the non-rigid sequence, through a real service with this many workers")
    args = parser.parse_args()
    if args.trajectory:
        trajectory()
        return
    if args.capacity:
        relaxation_capacity()
        return
    if args.shor:
        shor_capacity()
        return
    if args.nonrigid_service:
        nonrigid(60 if args.quick else 240, service_workers=args.nonrigid_service)
        return
    run(args.trials, args.quick)


if __name__ == "__main__":
    main()
