"""What the intervals over planes cost the verifier as the chirality rows grow (issue 33, review 29's
costly class): plane_sublevel bounds every box against every chirality row (the document's points,
then its cameras); the rows are tested CHIRALITY_PAIRS box-row pairs at a time and charged a unit
for every ROWS_PER_UNIT pairs (docs/certificate.md, "Sizes, and the verifier's cost").

The genuine 8-view, 60-point document (tests/solvers/autocalibration/test_autocalibration_over_planes
.solved, prove_intervals_over_planes) is solved, then: its whole verification (CPU seconds, peak
traced MB), and one block of its boxes (BLOCK_CAMERA_BOXES // 8 = 512 boxes) bounded with its
region's rows repeated to 10,000 and 30,000 (a document of more points), as CPU microseconds a
box and peak MB, each against the genuine 68 rows' block measured in this run (the ratio), with
the machine's load. Run it against two checkouts (PYTHONPATH) to compare them; CPU time, not
wall time, since the machine is shared.

    PYTHONPATH=. .venv/bin/python -m bench.plane_sublevel_rows

Nothing here asserts; tests/verify/test_forgeries_review29.py holds the checked cases.
"""

from __future__ import annotations

import copy
import json
import os
import time
import tracemalloc

import numpy as np

from geocert.jobs.runner import solve_job
from geocert.solvers.autocalibration import scenes
from geocert.formulations.autocalibration import plane_sublevel
from geocert.verify.checks import verify_any


def genuine() -> dict:
    scene = scenes.make_scene(8, 0.5, points=60, seed=1)
    return solve_job({"kind": "autocalibration", "data": scene.job_data(),
                      "options": {"certificate": "full", "prove_intervals_over_planes": True}})


def traced(call) -> tuple[float, float, object]:
    """(CPU seconds, peak traced MB, value) of one call."""
    tracemalloc.start()
    began = time.process_time()
    try:
        value = call()
        return time.process_time() - began, tracemalloc.get_traced_memory()[1] / 1e6, value
    finally:
        tracemalloc.stop()


def captured_block(document: dict) -> tuple:
    """The first 8-dimensional block the verifier bounds: (context, region, lo, hi)."""
    found: list = []
    original = plane_sublevel._excluded

    def capturing(context, region, lo, hi):
        if not found and lo.shape[1] == 8:
            found.append((context, region, lo.copy(), hi.copy()))
        return original(context, region, lo, hi)

    plane_sublevel._excluded = capturing
    try:
        verify_any(copy.deepcopy(document))
    finally:
        plane_sublevel._excluded = original
    return found[0]


def block(context, region, lo, hi, rows: int, repeats: int = 3) -> tuple[float, float]:
    """(CPU us a box, peak MB) of one block of BLOCK_CAMERA_BOXES camera-boxes at ``rows`` rows."""
    many = copy.copy(region)
    many.rows = np.tile(region.rows, (-(-rows // len(region.rows)), 1))[:max(rows, len(region.rows))]
    step = plane_sublevel.BLOCK_CAMERA_BOXES // len(context.problem.norm.cameras)
    boxes_lo, boxes_hi = np.resize(lo, (step, lo.shape[1])), np.resize(hi, (step, hi.shape[1]))
    _, peak, _ = traced(lambda: plane_sublevel.excluded(context, many, boxes_lo, boxes_hi))
    began = time.process_time()
    for _ in range(repeats):
        plane_sublevel.excluded(context, many, boxes_lo, boxes_hi)
    return (time.process_time() - began) / repeats / step * 1e6, peak


def main() -> None:
    print(f"load average (1 min) {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; plane_sublevel from "
          f"{plane_sublevel.__file__}")
    document = genuine()
    began = time.process_time()
    report = verify_any(json.loads(json.dumps(document)))
    seconds = time.process_time() - began
    _, peak, _ = traced(lambda: verify_any(json.loads(json.dumps(document))))
    print(f"genuine over-planes document: valid {report.valid}, verification {seconds:.2f} s CPU (untraced), "
          f"peak {peak:.1f} MB traced")
    context, region, lo, hi = captured_block(document)
    base_us, base_mb = block(context, region, lo, hi, len(region.rows))
    print(f"one block at {len(region.rows)} rows (the baseline): {base_us:.0f} us a box, peak {base_mb:.1f} MB")
    for rows in (10_000, 30_000):
        us, mb = block(context, region, lo, hi, rows)
        print(f"one block at {rows:,} rows: {us:.0f} us a box ({us / base_us:.1f}x), peak {mb:.1f} MB "
              f"({mb / base_mb:.1f}x)")
    print(f"load average (1 min) {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
