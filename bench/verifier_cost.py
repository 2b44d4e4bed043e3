"""What verifying costs, against what the document holds (docs/certificate.md, "Sizes, and the
verifier's cost"): seconds and peak memory per unit of document size for the stored genuine
certificates (tests/data/certificates), and for issue 33's class 7 (a direct certificate given
10,060 points: 36 s and 1.7 GB before its sizes were checked).
Each line is measured in this run; the baseline is the stored certificates' median, and the
machine's load is printed beside it.

    .venv/bin/python -m bench.verifier_cost [--points 10060]

Nothing here asserts; tests/verify/test_forgeries.py holds the checked cases.
"""

from __future__ import annotations

import argparse
import json
import os
import time
import tracemalloc
from pathlib import Path

import numpy as np

from geocert.core.certificates import data_hash, problem_hash
from geocert.core.strict import document_size
from geocert.verify.checks import verify_any

STORED = Path(__file__).resolve().parents[1] / "tests" / "data" / "certificates"


def measured(document: dict) -> tuple[float, float, bool, str]:
    """(seconds, peak MB, valid, first failure's detail) of one verification."""
    tracemalloc.start()
    began = time.perf_counter()
    report = verify_any(document)
    seconds = time.perf_counter() - began
    peak = tracemalloc.get_traced_memory()[1] / 1e6
    tracemalloc.stop()
    detail = (report.first_failure or {}).get("detail", "")
    return seconds, peak, report.valid, detail[:90]


def rehash(document: dict) -> dict:
    from geocert.kinds import get_kind

    names = getattr(get_kind(document["kind"]).verification, "claim_options", None)
    document["data_sha256"] = data_hash(document["kind"], document["data"])
    document["problem_sha256"] = problem_hash(document["kind"], document["data"], document["options"], names)
    return document


def many_points(count: int) -> dict:
    """The direct certificate with ``count`` copies of its points first (its exclusion shifted)."""
    document = json.loads((STORED / "autocalibration_direct_points.json").read_text())["certificate"]
    points = document["data"]["points"]
    document["data"]["points"] = [points[i % len(points)] for i in range(count)] + points
    for excluded in document["items"][0]["proof"]["excluded"]:
        excluded["rows"] = [row + count for row in excluded["rows"]]
    return rehash(document)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--points", type=int, default=10_060)
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cpus")
    rates = []
    print(f"{'document':40} {'size units':>11} {'s':>8} {'MB peak':>8} {'us/unit':>8}  verdict")
    for path in sorted(STORED.glob("*.json")):
        document = json.loads(path.read_text())
        size = document_size(document)
        seconds, peak, valid, detail = measured(document)
        rates.append(seconds / size)
        print(f"{path.stem:40} {size:11,d} {seconds:8.3f} {peak:8.1f} {1e6 * seconds / size:8.2f}  "
              f"{'valid' if valid else detail}")
    baseline = float(np.median(rates))
    print(f"baseline: {1e6 * baseline:.2f} us per unit of size (median of the stored certificates)")
    for name, document in ((f"direct, {args.points:,} points", many_points(args.points)),):
        size = document_size(document)
        seconds, peak, valid, detail = measured(document)
        print(f"{name:40} {size:11,d} {seconds:8.3f} {peak:8.1f} {1e6 * seconds / size:8.2f}  "
              f"{'valid' if valid else detail}  ({seconds / size / baseline:.2f} x the baseline per unit)")


if __name__ == "__main__":
    main()
