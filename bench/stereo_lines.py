"""Stereo line motion benchmark (thesis chapter 9; issue 16's tables). Synthetic scenes seen by the
thesis's rig (7.4 cm baseline, 320 px focal length on 640x480: 90 degrees of horizontal field of
view), lines 2 to 6 m away, frame-to-frame motions of 3 degrees and 10 cm. Prints:

1. per solver, the minimal solve's time (median, p99; 2 lines, linear 3);
2. per solver, RANSAC per frame pair with 100 lines, 30% outliers, 0.5 px noise: time (median,
   p99), samples drawn, rotation and translation errors, inliers found (with and without the
   refinement for the default solver);
3. rotation and translation errors versus noise, the four solvers side by side (as the thesis's
   synthetic experiments, Figures 9.4-9.6): the solver alone on 3 noisy lines, and inside RANSAC
   with the refinement on 100 lines;
3b. the thesis's own synthetic protocol (Figure 9.4: 0.1 baseline, lines in [-1, 1]^3, minimal
   samples, lower quartile);
4. frames per second end to end (matching from segments included) with 100 lines per frame;
5. a room of 30 boxes walked round once (180 frames, 0.5 px noise): the loop's drift;
6. a narrow-baseline corridor walk (issue 37): translations within 10%, marked, or neither; drift;
7. the defaults' throughput in fresh processes, beside another checkout's (--baseline-source).

    .venv/bin/python -m bench.stereo_lines [--instances 20] [--quick] [--baseline-source DIR ...] [--only 6,7]

Targets (issue 16): the polynomial minimal solver at most 100 us median; at least 30 frame pairs
per second end to end with 100 lines; rotation error at most 0.1 degrees per frame pair at 0.5 px.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from geocert.solvers.lines import align, incremental, linear, polynomial, scenes
from geocert.solvers.lines.geometry import line_set, rotation_error_deg
from geocert.solvers.lines.matching import STEREO_CACHE, MatchingOptions
from geocert.solvers.lines.pipeline import StereoLinesOptions, estimate_motion, estimate_pair
from geocert.solvers.lines.results import Degenerate

SOLVERS = {"polynomial": (polynomial.solve, 2), "linear": (linear.solve, 3), "incremental": (incremental.solve, 2),
           "align": (align.solve, 2)}


def motion_errors(motion, R, t) -> tuple[float, float]:
    """A motion's rotation error (degrees) and translation error (cm); a failed solve (None) counts
    as 180 degrees and 1 m."""
    if motion is None:
        return 180.0, 100.0
    return rotation_error_deg(motion.R, R), 100 * float(np.linalg.norm(motion.t - t))


def percentile(values, q) -> float:
    return float(np.percentile(values, q)) if len(values) else float("nan")


def minimal_times(count: int) -> None:
    print("\n1. Minimal solve (one sample, no RANSAC): microseconds")
    print("| solver | lines | median us | p99 us | candidates (median) |")
    print("|---|---|---|---|---|")
    rng = np.random.default_rng(1)
    for name, (solve, minimum) in SOLVERS.items():
        samples = [line_set(*(lambda s: (s.rig, s.segments))(scenes.pair_scene(rng, minimum))) for _ in range(count)]
        times, candidates = [], []
        for lines in samples:
            start = time.perf_counter()
            try:
                found = solve(lines)
            except Degenerate:
                found = []
            times.append(1e6 * (time.perf_counter() - start))
            candidates.append(len(found))
        print(f"| {name} | {minimum} | {np.median(times):.0f} | {percentile(times, 99):.0f} | "
              f"{np.median(candidates):.0f} |")


def ransac_table(instances: int) -> None:
    print("\n2. RANSAC per frame pair: 100 lines, 30% outliers, 0.5 px noise "
          f"({instances} pairs each; errors: median / p90)")
    print("| solver | sample | refine | median ms | p99 ms | samples | rotation deg | translation cm | "
          "inliers found | outliers kept |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    configurations = [("polynomial", 2, True), ("polynomial", 3, True), ("linear", 3, True), ("incremental", 2, True),
                      ("incremental", 3, True), ("incremental", 3, False), ("align", 2, True), ("align", 3, True)]
    for name, sample, refine in configurations:
        rng = np.random.default_rng(2)
        times, samples, rotation, translation, found, kept = [], [], [], [], [], []
        for _ in range(instances):
            scene = scenes.pair_scene(rng, 100, noise_px=0.5, outlier_fraction=0.3)
            options = StereoLinesOptions(solver=name, sample_size=sample, refine=refine)
            start = time.perf_counter()
            estimate = estimate_motion(line_set(scene.rig, scene.segments), options)
            times.append(1000 * (time.perf_counter() - start))
            samples.append(estimate.iterations)
            ok = estimate.status == "estimate"
            for errors, error in zip((rotation, translation), motion_errors(estimate if ok else None, scene.R, scene.t)):
                errors.append(error)
            if not ok:
                continue
            inliers, truth = set(estimate.inliers), set(np.flatnonzero(~scene.outliers))
            found.append(len(inliers & truth) / len(truth))
            kept.append(len(inliers - truth))
        print(f"| {name} | {sample} | {'yes' if refine else 'no'} | {np.median(times):.1f} | "
              f"{percentile(times, 99):.1f} | {np.median(samples):.0f} | {np.median(rotation):.3f} / "
              f"{percentile(rotation, 90):.3f} | {np.median(translation):.2f} / {percentile(translation, 90):.2f} | "
              f"{100 * np.mean(found):.0f}% | {np.mean(kept):.1f} |")


def noise_table(instances: int, noises=(0.0, 0.25, 0.5, 1.0, 2.0)) -> None:
    print(f"\n3. Errors versus noise (median over {instances}; rotation degrees / translation cm)")
    print("Solver alone on 3 lines (no outliers):")
    print("| noise px | " + " | ".join(SOLVERS) + " |")
    print("|---|" + "---|" * len(SOLVERS))
    for noise in noises:
        cells = []
        for name, (solve, _) in SOLVERS.items():
            rng = np.random.default_rng(3)
            rotation, translation = [], []
            for _ in range(instances):
                scene = scenes.pair_scene(rng, 3, noise_px=noise)
                try:
                    motion = solve(line_set(scene.rig, scene.segments))[0]
                except Degenerate:
                    motion = None
                for errors, error in zip((rotation, translation), motion_errors(motion, scene.R, scene.t)):
                    errors.append(error)
            cells.append(f"{np.median(rotation):.3f} / {np.median(translation):.2f}")
        print(f"| {noise} | " + " | ".join(cells) + " |")
    print("RANSAC (samples of 3) and refinement on 100 lines, 30% outliers:")
    print("| noise px | " + " | ".join(SOLVERS) + " |")
    print("|---|" + "---|" * len(SOLVERS))
    for noise in noises:
        cells = []
        for name in SOLVERS:
            rng = np.random.default_rng(4)
            rotation, translation = [], []
            for _ in range(instances):
                scene = scenes.pair_scene(rng, 100, noise_px=noise, outlier_fraction=0.3)
                estimate = estimate_motion(line_set(scene.rig, scene.segments),
                                           StereoLinesOptions(solver=name, sample_size=3))
                motion = estimate if estimate.status == "estimate" else None
                for errors, error in zip((rotation, translation), motion_errors(motion, scene.R, scene.t)):
                    errors.append(error)
            cells.append(f"{np.median(rotation):.3f} / {np.median(translation):.2f}")
        print(f"| {noise} | " + " | ".join(cells) + " |")


def thesis_setting(instances: int, noises=(0.0, 0.25, 0.5, 1.0, 2.0)) -> None:
    """The thesis's synthetic protocol (9.5.1, Figure 9.4): a 0.1-unit baseline, lines in the cube
    [-1, 1]^3, small motion, each solver on its minimum of 2 lines (linear 3), the lower quartile
    of the errors reported ("finding a fraction of good hypotheses" is what RANSAC needs). The
    cube's distance from the rig is not stated: here its centre is 3 units ahead."""
    print(f"\n3b. The thesis's synthetic protocol (Figure 9.4): baseline 0.1, lines in [-1, 1]^3 centred 3 units "
          f"ahead, 3 degrees / 0.1 units of motion, minimal samples, lower quartile over {instances} "
          "(rotation degrees / translation in units x 100)")
    print("| noise px | " + " | ".join(SOLVERS) + " |")
    print("|---|" + "---|" * len(SOLVERS))
    rig = scenes.thesis_rig(baseline=0.1)
    for noise in noises:
        cells = []
        for name, (solve, minimum) in SOLVERS.items():
            rng = np.random.default_rng(7)
            rotation, translation = [], []
            for _ in range(instances):
                R, t = scenes.random_motion(rng, 3.0, 0.1)
                X = rng.uniform(-1, 1, size=(minimum, 2, 3)) + np.array([0.0, 0.0, 3.0])
                segments = np.stack([*scenes.project(rig, X), *scenes.project(rig, X, R, t)], axis=1)
                segments = segments + rng.normal(scale=noise, size=segments.shape)
                try:
                    found = solve(line_set(rig, segments))
                    motion = min(found, key=lambda m: rotation_error_deg(m.R, R))
                except (Degenerate, np.linalg.LinAlgError):
                    motion = None
                for errors, error in zip((rotation, translation), motion_errors(motion, R, t)):
                    errors.append(error)
            cells.append(f"{percentile(rotation, 25):.3f} / {percentile(translation, 25):.2f}")
        print(f"| {noise} | " + " | ".join(cells) + " |")


def forget_matches(sequence: list[dict]) -> None:
    """Drop the left-right matches a previous configuration kept in the frames (each
    configuration is timed from the segments)."""
    for frame in sequence:
        frame.pop(STEREO_CACHE, None)


def end_to_end(frames: int) -> None:
    print(f"\n4. End to end from segments (matching, RANSAC, refinement), 100 lines per frame, 0.5 px noise, "
          f"{frames} frames, one core")
    print("| solver | sample | refine | guided | frame pairs/s | median ms | p99 ms | lines matched (median) | "
          "rotation deg (median) |")
    print("|---|---|---|---|---|---|---|---|---|")
    rig, poses, sequence = scenes.sequence(np.random.default_rng(5), frames, 100, noise_px=0.5, degrees=1.0,
                                           metres=0.03)
    for name, sample, refine, guided in (("incremental", 3, True, True), ("incremental", 3, False, True),
                                         ("incremental", 3, False, False), ("polynomial", 2, True, True),
                                         ("polynomial", 3, False, True)):
        options = StereoLinesOptions(solver=name, sample_size=sample, refine=refine,
                                     matching=MatchingOptions(guided=guided))
        forget_matches(sequence)
        times, matched, rotation = [], [], []
        for k in range(frames - 1):
            estimate, quads, seconds = estimate_pair(rig, sequence[k], sequence[k + 1], None, options)
            times.append(1000 * seconds)
            matched.append(len(quads))
            if estimate.status == "estimate":
                truth = poses[k + 1][0] @ poses[k][0].T
                rotation.append(rotation_error_deg(estimate.R, truth))
        print(f"| {name} | {sample} | {'yes' if refine else 'no'} | {'yes' if guided else 'no'} | "
              f"{1000 * len(times) / sum(times):.1f} | "
              f"{np.median(times):.1f} | {percentile(times, 99):.1f} | {np.median(matched):.0f} | "
              f"{np.median(rotation):.3f} |")


def room(frames: int) -> None:
    print(f"\n5. A room of 30 boxes walked round once ({frames} frames, 0.5 px noise, segments only): drift "
          "(a failed pair counts as no motion)")
    print("| solver | refine | guided | pairs failed | lines matched (median) | lines mistracked | rotation drift deg | "
          "position drift cm | % of the loop | frame pairs/s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    rig, poses, sequence, length = scenes.room_loop(np.random.default_rng(6), frames=frames, noise_px=0.5, boxes=30)
    for name, refine, guided in (("incremental", True, True), ("incremental", False, True),
                                 ("incremental", True, False), ("polynomial", True, True)):
        options = StereoLinesOptions(solver=name, sample_size=3, refine=refine,
                                     matching=MatchingOptions(guided=guided))
        forget_matches(sequence)
        R, t = np.eye(3), np.zeros(3)
        failed, matched, wrong, seconds = 0, [], 0, 0.0
        for k in range(len(sequence) - 1):
            a, b = sequence[k], sequence[k + 1]
            estimate, quads, spent = estimate_pair(rig, a, b, None, options)
            seconds += spent
            matched.append(len(quads))
            if len(quads):  # a matched line whose four segments are not of one scene line
                ids = np.stack([a["ids"][quads[:, 0]], a["ids"][quads[:, 1]], b["ids"][quads[:, 2]],
                                b["ids"][quads[:, 3]]], axis=1)
                wrong += int(np.sum(~np.all(ids == ids[:, :1], axis=1)))
            if estimate.status != "estimate":
                failed += 1  # carried over as no motion
                continue
            R, t = estimate.R @ R, estimate.R @ t + estimate.t
        R_true, t_true = poses[-1]
        drift = np.linalg.norm(-R.T @ t - (-R_true.T @ t_true))
        print(f"| {name} | {'yes' if refine else 'no'} | {'yes' if guided else 'no'} | {failed} | "
              f"{np.median(matched):.0f} | {100 * wrong / max(1, sum(matched)):.1f}% | "
              f"{rotation_error_deg(R, R_true):.2f} | {100 * drift:.1f} | {100 * drift / length:.2f}% | "
              f"{(len(sequence) - 1) / seconds:.1f} |")


def corridor(frames: int) -> None:
    """Issue 37's corridor walk (scenes.corridor_walk): 8 cm a frame, segments 2 to 8 m away, 0.5 px,
    30% of the lines matched wrongly. Per solver: how many pairs have their translation within 10%
    of its length, how many are marked as not determining it, and how many are neither (wrong and
    unmarked: the failure to avoid); the rotation errors; and the walk's drift (every pair's motion
    composed, marked or not, as a robot trusting them would)."""
    print(f"\n6. A corridor walk ({frames} frames, 8 cm a frame, segments 2 to 8 m away, 0.5 px, 30% wrong matches)")
    print("| solver | sample | pairs | t within 10% | t marked not determined | wrong and unmarked | rotation deg "
          "(median / max) | t error / length (median) | drift: position cm, % of the walk | drift: rotation deg |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    from geocert.jobs.runner import solve_job

    rig, poses, pairs = scenes.corridor_walk(np.random.default_rng(8), frames=frames)
    length = 0.08 * (frames - 1)
    per_pair: dict[str, list[str]] = {}
    for name, sample in (("incremental", 3), ("polynomial", 3)):
        result = solve_job({"kind": "stereo_lines", "options": {"solver": name, "sample_size": sample},
                            "data": {"rig": {"K_left": rig.K_left.tolist(), "K_right": rig.K_right.tolist(),
                                             "R": rig.R.tolist(), "t": rig.t.tolist()},
                                     "matches": [p.tolist() for p in pairs]}})
        within = marked = wrong = 0
        rotation, ratio = [], []
        R, t = np.eye(3), np.zeros(3)
        per_pair[name] = listed = []
        for k, item in enumerate(result["pairs"]):
            (Ra, ta), (Rb, tb) = poses[k], poses[k + 1]
            R_true, t_true = Rb @ Ra.T, tb - Rb @ Ra.T @ ta
            if item["status"] != "estimate":
                marked += 1
                listed.append("failed")
                continue
            Rk, tk = np.array(item["R"]), np.array(item["t"])
            error = float(np.linalg.norm(tk - t_true) / np.linalg.norm(t_true))
            rotation.append(rotation_error_deg(Rk, R_true))
            ratio.append(error)
            within += error <= 0.1
            marked += error > 0.1 and item["translation_determined"] is False
            wrong += error > 0.1 and item["translation_determined"] is not False
            listed.append(f"{error:.2f}{'' if item['translation_determined'] else '*'}")
            R, t = Rk @ R, Rk @ t + tk
        R_end, t_end = poses[-1]
        drift = float(np.linalg.norm(-R.T @ t - (-R_end.T @ t_end)))
        print(f"| {name} | {sample} | {len(result['pairs'])} | {within} | {marked} | {wrong} | "
              f"{np.median(rotation):.3f} / {max(rotation):.3f} | {np.median(ratio):.2f} | "
              f"{100 * drift:.1f}, {100 * drift / length:.0f}% | {rotation_error_deg(R, R_end):.2f} |")
    print("Each pair's translation error over the step's length (*: marked as not determining its translation):")
    for name, listed in per_pair.items():
        print(f"  {name}: {' '.join(listed)}")


def throughput(baselines: list[str], frames: int, rounds: int = 5) -> None:
    """Section 4's default configuration timed in fresh processes, this checkout's and (with
    --baseline-source, which may be given more than once) others', in turn, ``rounds`` times each:
    pairs per second of wall time and of the process's CPU time (less sensitive to what else
    runs), medians and bests (on a shared machine the best of a few runs is the least disturbed),
    and their ratios. The target (issue 16): at least 30 pairs per CPU second."""
    import subprocess
    import sys
    from pathlib import Path

    code = ("import time, numpy as np\n"
            "from geocert.solvers.lines import scenes\n"
            "from geocert.solvers.lines.pipeline import StereoLinesOptions, estimate_pair\n"
            f"rig, poses, seq = scenes.sequence(np.random.default_rng(5), {frames}, 100, noise_px=0.5, degrees=1.0, "
            "metres=0.03)\n"
            "options = StereoLinesOptions()\n"
            "wall, cpu = time.perf_counter(), time.process_time()\n"
            f"for k in range({frames - 1}):\n"
            "    estimate_pair(rig, seq[k], seq[k + 1], None, options)\n"
            f"print({frames - 1} / (time.perf_counter() - wall), {frames - 1} / (time.process_time() - cpu))\n")
    here = str(Path(__file__).resolve().parents[1])
    sources = {"this checkout": here, **{f"baseline {source}": source for source in baselines}}
    found: dict[str, list] = {name: [] for name in sources}
    for _ in range(rounds):
        for name, source in sources.items():
            env = {**os.environ, "PYTHONPATH": source, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
            out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=source,
                                 check=True)
            found[name].append([float(x) for x in out.stdout.split()])
    print(f"\n7. Throughput with the defaults ({frames - 1} frame pairs of section 4's sequence, fresh processes in "
          f"turn, one BLAS thread, {rounds} rounds: median / best)")
    print("| code | frame pairs/s (wall) | frame pairs per CPU second |")
    print("|---|---|---|")
    for name, rows in found.items():
        rows = np.array(rows)
        print(f"| {name} | {np.median(rows[:, 0]):.1f} / {rows[:, 0].max():.1f} | "
              f"{np.median(rows[:, 1]):.1f} / {rows[:, 1].max():.1f} |")
    mine = np.array(found["this checkout"])
    for source in baselines:
        theirs = np.array(found[f"baseline {source}"])
        print(f"ratio (this checkout / baseline {source}), CPU: median {np.median(mine[:, 1]) / np.median(theirs[:, 1]):.2f}, "
              f"best {mine[:, 1].max() / theirs[:, 1].max():.2f}; wall: median "
              f"{np.median(mine[:, 0]) / np.median(theirs[:, 0]):.2f}, best {mine[:, 0].max() / theirs[:, 0].max():.2f}")
    rate = np.median(mine[:, 1])
    print(f"at least 30 frame pairs per CPU second (median): {'met' if rate >= 30 else 'MISSED'} ({rate:.1f})")


def machine() -> str:
    """The load and a fixed workload's time: this 2-core machine is shared, and every time above
    scales with what else runs (the figures of one run are comparable with each other only)."""
    start = time.perf_counter()
    a = np.random.default_rng(0).normal(size=(4, 4))
    for _ in range(20_000):
        np.linalg.svd(a)
    return f"load average {os.getloadavg()[0]:.1f}, 20k 4x4 SVDs {1000 * (time.perf_counter() - start):.0f} ms"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--instances", type=int, default=20)
    parser.add_argument("--quick", action="store_true", help="fewer instances and frames")
    parser.add_argument("--baseline-source", action="append", default=[],
                        help="another checkout (e.g. main's) whose defaults section 7 times beside this one's "
                             "(may be given more than once)")
    parser.add_argument("--only", help="comma-separated sections to run (e.g. 6,7)")
    args = parser.parse_args()
    instances = 5 if args.quick else args.instances
    began = time.time()
    print(f"machine at the start: {machine()}")
    only = set(args.only.split(",")) if args.only else None
    sections = [("1", lambda: minimal_times(60 if args.quick else 300)), ("2", lambda: ransac_table(instances)),
                ("3", lambda: noise_table(instances)), ("3b", lambda: thesis_setting(40 if args.quick else 200)),
                ("4", lambda: end_to_end(10 if args.quick else 40)),
                ("5", lambda: room(180)),  # 2 degrees and 4 cm a frame: a slower walk is not faster to bench
                ("6", lambda: corridor(12 if args.quick else 40)),
                ("7", lambda: throughput(args.baseline_source, 11 if args.quick else 41))]
    for name, run in sections:
        if only is None or name in only:
            run()
    print(f"\nmachine at the end: {machine()} (ran in {time.time() - began:.0f} s)")


if __name__ == "__main__":
    main()
