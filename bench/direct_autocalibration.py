"""Direct autocalibration benchmark (issue 13): thesis Table 7.1's protocol in miniature.

Scenes (geocert.solvers.autocalibration.scenes.table71_scene): 12 cameras at distance 2 looking
at 15 points in [-1, 1]^3, K = I (fixed focal) or diag(f, f, 1) with f in [0.05, 1] per view
(varying focal), 0.2% noise of the image size (2 units; scaled by f when it varies) added before
each camera is DLT-resected, a random projective frame. Each scene is solved through the kind
(geocert.jobs.runner.solve_job, method "direct"), without and with chirality ("points").

Prints, per column (as Table 7.1): mean errors of (7.17) against ground truth (df = |f1/f1' - 1|
+ |f2/f2' - 1|, dr = max(r/r', r'/r) with r = f1/f2, dp = (|u| + |v|)/2 - (|u'| + |v'|)/2,
ds = |s - s'|; per view and averaged when the focal length varies), the fraction of cameras with
every point in front (the chirality check), the median trial's df, the errors of the K the same
noisy input cameras give with the scene's true quadric (*_true_Q: what the true quadric itself
scores, i.e. the error that is the cameras' own noise; with varying focal each view's K carries its
own camera's), the certified fraction, the rank-one fraction of the
moment matrix, the fraction both rank one and certified (rank1_cert), numerical failures (no clean
solve or no answer), and the time per solve (median, max); the thesis's numbers beside ours; then
issue 13's targets, each named met or MISSED. With --stratified, the stratified method on the same
fixed-focal scenes in a last column (intrinsics ranges: focal [0.5, 2], the same small ranges).

    .venv/bin/python -m bench.direct_autocalibration [--trials 10] [--first-trial 0] [--stratified] [--time-limit 10] [--jobs 1]
        [--rows rows.jsonl]   (or --from-rows rows.jsonl: the table of the trials run so far)
    .venv/bin/python -m bench.direct_autocalibration --speed [--trials 5]   (issue 38: against the former
        Schur complement assembly in the same run, the ratio printed)
    .venv/bin/python -m bench.direct_autocalibration --speed --against ../other-checkout [--trials 5]
        (against another checkout's code, each in its own process, solves interleaved)

--jobs runs that many solves at once (each single-threaded); the load average is printed before
and after, since times on a shared machine are inflated by the other work on it.
"""

from __future__ import annotations

import os

import bench.one_blas_thread  # noqa: F401  (before numpy: one BLAS thread, as the workers have)

import argparse  # noqa: E402
import functools  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from geocert.jobs.runner import solve_job  # noqa: E402
from geocert.solvers.autocalibration import scenes  # noqa: E402

UNIT = {"aspect": [0.95, 1.05], "skew": [-0.01, 0.01], "principal_point": [[-0.1, 0.1], [-0.1, 0.1]]}
# Table 7.1 (means over 100 trials): fixed focal without / with chirality, varying without / with.
THESIS = {"df": (0.0086, 0.0360, 0.0069, 0.0328), "dr": (1.0041, 1.0315, 1.0027, 1.0272),
          "dp": (0.0073, 0.0096, 0.0055, 0.0098), "ds": (0.0051, 0.0092, 0.0033, 0.0050),
          "chirality": (None, 0.9867, None, 0.9942), "failed": (2, 2, 4, 1)}
COLUMNS = (("fixed", False, "none"), ("fixed", False, "points"), ("varying", True, "none"), ("varying", True, "points"))


def errors(K: np.ndarray, truth: np.ndarray) -> dict:
    f1, f2, s, u, v = K[0, 0], K[1, 1], K[0, 1], K[0, 2], K[1, 2]
    t1, t2 = truth[0, 0], truth[1, 1]
    r, rt = f1 / f2, t1 / t2
    return {"df": abs(f1 / t1 - 1) + abs(f2 / t2 - 1), "dr": max(r / rt, rt / r),
            "dp": (abs(u) + abs(v)) / 2 - (abs(truth[0, 2]) + abs(truth[1, 2])) / 2, "ds": abs(s - truth[0, 1])}


@functools.lru_cache(maxsize=None)
def true_quadric_errors(seed: int, varying: bool) -> dict:
    """(7.17)'s errors of the K the result would state if it returned the scene's true quadric
    (Hp^-1 diag(1, 1, 1, 0) Hp^-T, read from the same noisy input cameras as ours: one K, the mean
    of the views' normalised P_i Q P_i', with constant focal; each view's own with varying focal):
    the error the camera noise alone makes (no solve; from the seed)."""
    from geocert.formulations.autocalibration import direct

    scene, Ks = scenes.table71_scene(seed, 0.2, varying)
    Hinv = np.linalg.inv(scene.projective)
    Q = Hinv @ np.diag([1.0, 1.0, 1.0, 0.0]) @ Hinv.T
    estimates = direct.calibrations(scene.cameras, Q) if varying else [direct.mean_calibration(scene.cameras, Q)] * len(Ks)
    rows = [errors(K, truth) for K, truth in zip(estimates, Ks)]
    return {key: float(np.mean([row[key] for row in rows])) for key in rows[0]}


def in_front(result: dict) -> float:
    points = np.array([p for p in result["points"] if p is not None])
    good = [np.all((points - np.array(c["center"])) @ np.array(c["R"])[2] > 0) for c in result["cameras"]]
    return float(np.mean(good))


def trial(seed: int, varying: bool, chirality: str, method: str = "direct", time_limit: float = 10.0) -> dict:
    scene, Ks = scenes.table71_scene(seed, 0.2, varying)
    data = {"cameras": scene.cameras.tolist(), "points": scene.points.tolist()}
    options = {"method": method, "intrinsics": {**UNIT, "focal": [0.05, 1.0] if varying else [0.5, 2.0]}}
    if method == "direct":  # measured to its end, as before it kept a time limit
        options.update(chirality=chirality, varying_focal=varying, time_limit_s=3600)
    else:
        options.update(time_limit_s=time_limit)
    start, cpu = time.perf_counter(), time.process_time()
    try:
        result = solve_job({"kind": "autocalibration", "data": data, "options": options})
    except Exception as exc:  # a crash counts as a numerical failure
        return {"failed": True, "time": time.perf_counter() - start, "cpu": time.process_time() - cpu,
                "error": str(exc)}
    elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
    stages = result["stages"]
    estimates = result["Ks"] if varying else [result["K"]] * len(Ks)
    if any(K is None for K in (estimates or [None])):
        return {"failed": True, "time": elapsed, "cpu": cpu, "error": f"no K ({stages[-1].get('reason')})"}
    rows = [errors(np.array(K), truth) for K, truth in zip(estimates, Ks)]
    out = {key: float(np.mean([row[key] for row in rows])) for key in rows[0]}
    last = stages[-1]
    out.update(time=elapsed, cpu=cpu, certified=all(s["certified"] for s in stages), chirality=in_front(result),
               rank_one=(last.get("certificate") or {}).get("moment_rank") == 1,
               failed=any(s["status"] == "failed" for s in stages) or "AlmostSolved" in str(
                   (last.get("certificate") or {}).get("conic_status")))
    return out


def column(rows: list[dict]) -> dict:
    ok = [r for r in rows if "df" in r]
    times = [r["time"] for r in rows]
    summary = {key: float(np.mean([r[key] for r in ok])) if ok else float("nan")
               for key in ("df", "dr", "dp", "ds", "chirality")}
    floors = [true_quadric_errors(r["task"][0], bool(r["task"][1])) for r in ok]
    summary["df_median"] = float(np.median([r["df"] for r in ok])) if ok else float("nan")
    summary.update({f"{key}_true_Q": float(np.mean([f[key] for f in floors])) if ok else float("nan")
                    for key in ("df", "dr", "dp", "ds")})
    summary.update(certified=float(np.mean([r.get("certified", False) for r in rows])),
                   rank_one=float(np.mean([r.get("rank_one", False) for r in rows])),
                   rank1_cert=float(np.mean([r.get("rank_one", False) and r.get("certified", False)
                                                     for r in rows])),
                   failed=sum(bool(r.get("failed")) for r in rows), median_s=float(np.median(times)),
                   max_s=float(max(times)), median_cpu_s=float(np.median([r["cpu"] for r in rows if "cpu" in r] or [np.nan])),
                   max_cpu_s=float(max([r["cpu"] for r in rows if "cpu" in r] or [np.nan])))
    return summary


def targets(names: list[str], results: list[dict]) -> None:
    """Issue 13's targets, each named met or MISSED, per direct column."""
    direct = list(zip(names[:4], results[:4]))
    print("Targets (issue 13), direct columns:")
    # compared at Table 7.1's printed precision (4 decimals): its 0.0086 is any mean in [0.00855, 0.00865)
    worse = [f"{key} {name} {summary[key]:.4f} > {THESIS[key][i]:.4f}"
             + f" (the true quadric's own: {summary[key + '_true_Q']:.4f})"
             for i, (name, summary) in enumerate(direct)
             for key in ("df", "dr", "dp", "ds") if round(summary[key], 4) > THESIS[key][i]]
    print(f"  accuracy at least Table 7.1's (4 decimals): {'met' if not worse else 'MISSED: ' + '; '.join(worse)}")
    fails = [f"{name} {summary['failed']}" for name, summary in direct if summary["failed"]]
    print(f"  zero numerical failures: {'met' if not fails else 'MISSED: ' + ', '.join(fails)}")
    low = [f"{name} {summary['rank1_cert']:.2f}" for name, summary in direct
           if summary["rank1_cert"] < 0.95]
    print(f"  rank-one certified in >= 95% of trials: {'met' if not low else 'MISSED: ' + ', '.join(low)}")
    slow = [f"{name} {summary['median_cpu_s']:.1f}" for name, summary in direct if not summary["median_cpu_s"] <= 5.0]
    wall = ", ".join(f"{summary['median_s']:.1f}" for _, summary in direct)
    print(f"  median solve <= 5 s (processor time): {'met' if not slow else 'MISSED: ' + ', '.join(slow)}"
          f" (wall medians {wall})")


def _timed(seed: int, varying: bool, chirality: str) -> dict:
    """One direct solve through the kind: its processor seconds, the K it states (each view's with
    varying focal), whether it is certified, and its lower bound."""
    scene, _ = scenes.table71_scene(seed, 0.2, varying)
    options = {"method": "direct", "chirality": chirality, "varying_focal": varying, "time_limit_s": 3600,
               "intrinsics": {**UNIT, "focal": [0.05, 1.0] if varying else [0.5, 2.0]}}
    cpu = time.process_time()
    result = solve_job({"kind": "autocalibration", "data": {"cameras": scene.cameras.tolist(),
                                                            "points": scene.points.tolist()}, "options": options})
    cpu = time.process_time() - cpu
    Ks = result["Ks"] if varying else [result["K"]]
    return {"cpu": cpu, "Ks": None if any(K is None for K in Ks or [None]) else np.array(Ks),
            "certified": all(stage["certified"] for stage in result["stages"]),
            "bound": result["stages"][-1].get("lower_bound")}


def speed(trials: int, first: int) -> None:
    """Issue 38: the direct method's processor time with the Schur complement assembled per moment
    (interior_point.ASSEMBLY "moments") against the former assembly ("kron": the svec operator and
    sparse products), each trial solved both ways one after the other (the order alternating), on
    Table 7.1's scenes (seeds 1000 + first onwards, the four columns); one warm-up solve each first.
    Prints per column the median processor seconds, their ratio, the largest relative difference
    of the certified K, and the certified counts."""
    from geocert.core import interior_point

    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())} ({os.cpu_count()} cores)", flush=True)
    for assembly in ("kron", "moments"):
        interior_point.ASSEMBLY = assembly
        _timed(999, False, "none")
    names = [f"{focal}/{'chir' if chirality == 'points' else 'no chir'}" for focal, _, chirality in COLUMNS]
    out = {name: {"kron": [], "moments": []} for name in names}
    for i in range(first, first + trials):
        for name, (_, varying, chirality) in zip(names, COLUMNS):
            for assembly in (("kron", "moments") if i % 2 == 0 else ("moments", "kron")):
                interior_point.ASSEMBLY = assembly
                out[name][assembly].append(_timed(1000 + i, varying, chirality))
    interior_point.ASSEMBLY = "moments"
    print(f"direct autocalibration, {trials} trials per column (seeds {1000 + first} to {1000 + first + trials - 1}), "
          "processor seconds a solve (one BLAS thread)")
    _print_table(out, names, "kron", "moments")


def _print_table(out: dict, names: list, first: str, second: str) -> None:
    """Per column the median processor seconds of the ``first`` and ``second`` runs, their ratio,
    the largest relative difference of K and the certified counts; then over all columns."""
    print(f"{'column':<18}{first:>12}{second:>12}{'ratio':>8}{'max |dK|/|K|':>14}"
          f"{f'certified {first}/{second}':>26}")
    for name in names:
        old, new = out[name][first], out[name][second]
        a, b = float(np.median([r["cpu"] for r in old])), float(np.median([r["cpu"] for r in new]))
        diffs = [float(np.max(np.abs(np.asarray(x["Ks"]) - np.asarray(y["Ks"]))) / np.max(np.abs(np.asarray(x["Ks"]))))
                 for x, y in zip(old, new) if x["Ks"] is not None and y["Ks"] is not None]
        print(f"{name:<18}{a:>12.3f}{b:>12.3f}{a / b:>8.2f}{max(diffs) if diffs else float('nan'):>14.1e}"
              f"{sum(r['certified'] for r in old):>18d}/{sum(r['certified'] for r in new)}")
    every_old = [r["cpu"] for name in names for r in out[name][first]]
    every_new = [r["cpu"] for name in names for r in out[name][second]]
    print(f"{'all':<18}{np.median(every_old):>12.3f}{np.median(every_new):>12.3f}"
          f"{np.median(every_old) / np.median(every_new):>8.2f}")
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


def _worker() -> None:
    """--worker: one solve (_timed) per JSON line [seed, varying, chirality] on stdin, its answer a
    JSON line on stdout; the geocert it runs is whichever PYTHONPATH selects (speed_against)."""
    import sys

    for line in sys.stdin:
        seed, varying, chirality = json.loads(line)
        row = _timed(seed, varying, chirality)
        row["Ks"] = None if row["Ks"] is None else row["Ks"].tolist()
        print(json.dumps(row), flush=True)


def speed_against(other: str, trials: int, first: int) -> None:
    """Issue 38: this checkout's direct method against the geocert of checkout ``other`` (a path),
    each in its own long-lived worker process (--worker, PYTHONPATH choosing the code), the same
    scene solved by both one after the other (the order alternating), so both see the same load;
    one warm-up solve each first. Prints per column the median processor seconds, their ratio, the
    largest relative difference of K and the certified counts."""
    import subprocess
    import sys

    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    workers = {}
    for name, root in (("before", os.path.abspath(other)), ("after", here)):
        env = {**os.environ, "PYTHONPATH": root}
        workers[name] = subprocess.Popen([sys.executable, os.path.abspath(__file__), "--worker"], env=env, cwd=root,
                                         stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)

    def ask(name: str, task: list) -> dict:
        workers[name].stdin.write(json.dumps(task) + "\n")
        workers[name].stdin.flush()
        return json.loads(workers[name].stdout.readline())

    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())} ({os.cpu_count()} cores)", flush=True)
    for name in workers:
        ask(name, [999, False, "none"])
    names = [f"{focal}/{'chir' if chirality == 'points' else 'no chir'}" for focal, _, chirality in COLUMNS]
    out = {name: {"before": [], "after": []} for name in names}
    for i in range(first, first + trials):
        for name, (_, varying, chirality) in zip(names, COLUMNS):
            for which in (("before", "after") if i % 2 == 0 else ("after", "before")):
                out[name][which].append(ask(which, [1000 + i, varying, chirality]))
    for worker in workers.values():
        worker.stdin.close()
        worker.wait()
    print(f"direct autocalibration, {trials} trials per column (seeds {1000 + first} to {1000 + first + trials - 1}), "
          f"processor seconds a solve (one BLAS thread); before: {os.path.abspath(other)}, after: {here}")
    _print_table(out, names, "before", "after")


def _run(task: tuple) -> dict:
    return {"task": list(task), **trial(*task)}


def _column_of(task: list) -> str:
    if len(task) > 3 and task[3] == "stratified":
        return "stratified fixed"
    return f"{'varying' if task[1] else 'fixed'}/{'chir' if task[2] == 'points' else 'no chir'}"


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--first-trial", type=int, default=0,
                        help="trials are seeds 1000 + first-trial onwards (to extend a --rows file)")
    parser.add_argument("--stratified", action="store_true")
    parser.add_argument("--time-limit", type=float, default=10.0, help="per stratified stage (s)")
    parser.add_argument("--jobs", type=int, default=1, help="solves run at once")
    parser.add_argument("--rows", help="append each trial's row to this JSON-lines file as it ends")
    parser.add_argument("--from-rows", help="print the table of the trials in this file, solving nothing")
    parser.add_argument("--speed", action="store_true",
                        help="issue 38: processor time against the former Schur assembly, same run (prints the ratio)")
    parser.add_argument("--against", metavar="CHECKOUT",
                        help="with --speed: against that checkout's geocert (a path), each in its own process")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        _worker()
        return
    if args.speed and args.against:
        speed_against(args.against, args.trials, args.first_trial)
        return
    if args.speed:
        speed(args.trials, args.first_trial)
        return
    if args.from_rows:
        with open(args.from_rows) as handle:
            rows = [json.loads(line) for line in handle if line.strip()]
    else:
        print(f"load average before: {' '.join(f'{x:.1f}' for x in os.getloadavg())} ({os.cpu_count()} cores)",
              flush=True)
        # seed-major, so that an interrupted run (--rows) has every column about equally far
        tasks = []
        for i in range(args.first_trial, args.first_trial + args.trials):
            tasks += [(1000 + i, varying, chirality) for _, varying, chirality in COLUMNS]
            if args.stratified:
                tasks.append((1000 + i, False, "none", "stratified", args.time_limit))
        out = open(args.rows, "a") if args.rows else None
        rows = []
        if args.jobs > 1:
            from multiprocessing import Pool

            pool = Pool(args.jobs)
            results = pool.imap_unordered(_run, tasks, chunksize=1)
        else:
            results = map(_run, tasks)
        for row in results:
            rows.append(row)
            if out:
                out.write(json.dumps(row) + "\n")
                out.flush()
        if args.jobs > 1:
            pool.close()
    names = [f"{focal}/{'chir' if chirality == 'points' else 'no chir'}" for focal, _, chirality in COLUMNS]
    if any(_column_of(row["task"]) == "stratified fixed" for row in rows):
        names.append("stratified fixed")
    grouped = {name: [row for row in rows if _column_of(row["task"]) == name] for name in names}
    results = [column(grouped[name]) for name in names]
    counts = sorted({len(group) for group in grouped.values()})
    args.trials = "/".join(map(str, counts))
    print(f"Table 7.1 in miniature: {args.trials} trials per column (thesis: 100), 12 views, 15 points, 0.2% noise")
    print(f"{'quantity':<12}" + "".join(f"{n:>18}" for n in names))
    for key in ("df", "dr", "dp", "ds", "chirality"):
        line = f"{key:<12}"
        for i, summary in enumerate(results):
            thesis = THESIS[key][i] if i < 4 else None
            text = f"{summary[key]:.4f}" + (f" ({thesis:.4f})" if thesis is not None else " (n/a)" if i < 4 else "")
            line += f"{text:>18}"
        print(line)
    for key in ("df_median", "df_true_Q", "dr_true_Q", "dp_true_Q", "ds_true_Q"):
        print(f"{key:<12}" + "".join(f"{summary[key]:.4f}".rjust(18) for summary in results))
    for key, fmt in (("certified", "{:.2f}"), ("rank_one", "{:.2f}"), ("rank1_cert", "{:.2f}"),
                     ("failed", "{:d}"), ("median_s", "{:.1f}"),
                     ("max_s", "{:.1f}"), ("median_cpu_s", "{:.1f}"), ("max_cpu_s", "{:.1f}")):
        line = f"{key:<12}"
        for i, summary in enumerate(results):
            text = fmt.format(summary[key])
            if key == "failed" and i < 4:
                text += f" ({THESIS['failed'][i]})"
            line += f"{text:>18}"
        print(line)
    print("(df_median: the median trial's df; *_true_Q: the mean errors of the K read from the same noisy input "
          "cameras with the scene's true quadric, the error camera noise alone makes: with varying "
          "focal each view's K carries its own camera's noise, with constant focal one K averages 12 views)")
    print("(thesis's Table 7.1 in parentheses; rank_one and certified are ours: the thesis reports neither. "
          "median_s/max_s are wall seconds per solve on this machine, shared; "
          "*_cpu_s the solve's own processor seconds, what it takes on an idle core.)")
    targets(names, results)
    if not args.from_rows:
        print(f"load average after: {' '.join(f'{x:.1f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
