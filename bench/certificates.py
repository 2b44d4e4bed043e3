"""Certificate benchmark: size and verification time against solve time, on the Oxford Dinosaur
(Oxford VGG data): every track triangulated, and every camera resected from the points our
certified triangulation gives for the tracks it sees.

For each item, in one run: the solve with a summary certificate, the solve with a full one, the
JSON size of its certificate, and the time `geocert.verify` takes to check it. Prints totals,
medians and the ratio of verification to solve time (target: at most 1).

``--job``: instead, the tracks as one triangulation job with ``certificate: "full"`` under each
norm, as the service returns it: the whole result document's bytes per track (the certificate
with the job's data, and the items; issue 18's target: at most 5 KiB on average) and the
verifier's rate on it, tracks per second of one core's processor time (target: at least 2,000).

    .venv/bin/python -m bench.certificates [--norm L2L2] [--tracks N] [--cameras N] [--rel-gap-maps 1e-2] [--job]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import time

import numpy as np

from bench.resection import DATA, dinosaur_problems
from geocert.solvers.datasets import load_dinosaur
from geocert.solvers.fractional.maps import MapOptions, fit_map
from geocert.solvers.fractional.triangulation import TriangulationOptions, triangulate
from geocert.formulations.fractional.results import claim_of
from geocert.verify.checks import verify_arrays


def measure(kind: str, items, solve, options, solution) -> dict:
    """Per item: summary solve time, full solve time, certificate bytes, verification time."""
    rows = []
    for arrays in items:
        start = time.perf_counter()
        solve(*arrays, dataclasses.replace(options, certificate="summary"))
        summary_s = time.perf_counter() - start
        start = time.perf_counter()
        result = solve(*arrays, dataclasses.replace(options, certificate="full"))
        full_s = time.perf_counter() - start
        if not result.certified:
            rows.append((summary_s, full_s, 0, 0.0, False))
            continue
        claim = claim_of(result, **solution(result))
        text = json.dumps(claim, separators=(",", ":"))
        start = time.perf_counter()
        verify_arrays(kind, arrays, dataclasses.asdict(options), json.loads(text))
        verify_s = time.perf_counter() - start
        rows.append((summary_s, full_s, len(text), verify_s, True))
    return summarise(rows)


def summarise(rows) -> dict:
    summary, full, size, verify, ok = (np.array(column) for column in zip(*rows))
    return {"items": len(rows), "certified": int(ok.sum()), "summary_s": summary.sum(), "full_s": full.sum(),
            "verify_s": verify.sum(), "bytes": int(size.sum()), "bytes_median": float(np.median(size[ok])),
            "bytes_max": int(size.max()), "verify_median_ms": 1e3 * float(np.median(verify[ok])),
            "full_median_ms": 1e3 * float(np.median(full[ok])), "ratio_median": float(np.median(verify[ok] / full[ok])),
            "ratio_max": float(np.max(verify[ok] / full[ok]))}


def report(name: str, figures: dict) -> None:
    f = figures
    print(f"{name:24} {f['certified']:>5}/{f['items']:<5} solve {f['summary_s']:8.1f} s  full {f['full_s']:8.1f} s  "
          f"verify {f['verify_s']:8.1f} s  ratio total {f['verify_s'] / f['full_s']:.2f} "
          f"median {f['ratio_median']:.2f} max {f['ratio_max']:.2f}  size {f['bytes'] / 1e6:8.2f} MB "
          f"(median {f['bytes_median'] / 1e3:.1f} kB, max {f['bytes_max'] / 1e3:.1f} kB)  "
          f"per item: full {f['full_median_ms']:.1f} ms, verify {f['verify_median_ms']:.1f} ms (medians)")


def job_figures(norm: str, cameras, tracks) -> None:
    """One full-certificate job of the tracks: document bytes per track, verification rate."""
    from geocert.jobs.runner import solve_job
    from geocert.verify.checks import verify_any

    job = {"kind": "triangulation", "options": {"norm": norm, "certificate": "full"},
           "data": {"cameras": cameras.tolist(),
                    "tracks": [{"views": [int(v) for v in t.views], "points": t.points.tolist()} for t in tracks]}}
    started = time.process_time()
    result = solve_job(job)
    solve_cpu = time.process_time() - started
    text = json.dumps(result, separators=(",", ":"))
    certificate = json.dumps(result["certificate"], separators=(",", ":"))
    document = json.loads(text)
    started = time.process_time()
    report = verify_any(document)
    verify_cpu = time.process_time() - started
    n = len(tracks)
    print(f"{norm}: {n} tracks, {report.items_checked} certified claims checked, valid {report.valid}; "
          f"result document {len(text) / n / 1024:.2f} KiB/track (certificate {len(certificate) / n / 1024:.2f}, "
          f"target <= 5); verify {verify_cpu:.1f} s CPU = {n / verify_cpu:.0f} tracks/s (target >= 2000); "
          f"solve {solve_cpu:.1f} s CPU = {n / solve_cpu:.0f} tracks/s", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--norm", default="L2L2")
    parser.add_argument("--tracks", type=int, default=0, help="evenly spaced tracks (0: all 4983)")
    parser.add_argument("--cameras", type=int, default=0, help="evenly spaced cameras (0: all 36)")
    parser.add_argument("--rel-gap-maps", type=float, default=1e-2)
    parser.add_argument("--job", action="store_true", help="the tracks as one job per norm (see above)")
    args = parser.parse_args()
    os.environ["GEOCERT_SELF_VERIFY"] = "0"  # time the solver alone; the verifier is timed on its own
    cameras, tracks = load_dinosaur(DATA / "oxford_dinosaur")
    if args.tracks:
        tracks = [tracks[i] for i in np.linspace(0, len(tracks) - 1, args.tracks).astype(int)]
    if args.job:
        for norm in ("L2L2", "L2L1", "L1L1"):
            job_figures(norm, cameras, tracks)
        return
    items = [(cameras[t.views], t.points) for t in tracks]
    report(f"Dinosaur tracks {args.norm}", measure("triangulation", items, triangulate, TriangulationOptions(norm=args.norm),
                                                   lambda r: {"point": r.point, "at_infinity": r.at_infinity}))
    problems = dinosaur_problems()
    if args.cameras:
        problems = [problems[i] for i in np.linspace(0, len(problems) - 1, args.cameras).astype(int)]
    report(f"Dinosaur cameras {args.norm}", measure("resection", problems, fit_map,
                                                    MapOptions(norm=args.norm, rel_gap=args.rel_gap_maps),
                                                    lambda r: {"matrix": r.matrix}))


if __name__ == "__main__":
    main()
