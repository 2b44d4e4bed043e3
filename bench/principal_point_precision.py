"""How precisely the data fix each view's principal point in a saved result with a principal point
per view (``bench.reconstruction_vs_colmap --options '{"principal_point": "per_view"}' --results
DIR``): each view's principal point's marginal standard deviation in pixels, linearised at the
returned cameras and points (solvers.reconstruction.principal_points: the reduced camera system,
the points, the shared focal length and the other views free, the similarity's 7 directions left
out), beside its distance from the views' median. A principal
point the per-view test frees but the data fix only to tens of pixels trades with the view's
rotation (bench/results/reconstruction_vs_colmap.md: templeSparseRing against Sceaux).

    .venv/bin/python -m bench.principal_point_precision RESULT.json [RESULT.json ...]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from geocert.solvers.reconstruction import principal_points

def precision(result: dict) -> dict:
    """{"views", "sigma_px", "sd_px", "offset_px", "null"} of a result whose cameras have a K each."""
    cameras = {c["view"]: c for c in result["cameras"] if c.get("registered") and c.get("K") is not None}
    views = sorted(cameras)
    index = {v: k for k, v in enumerate(views)}
    rows, X = [], []
    for point in result["points"]:
        if point.get("point") is None or point.get("at_infinity"):
            continue
        for v, u, w in point["observations"]:
            if v in index:
                rows.append((index[v], len(X), u, w))
        X.append(point["point"])
    rows = np.array(rows, dtype=float)
    Ks = np.array([cameras[v]["K"] for v in views], dtype=float)
    sd, sigma, null = principal_points.standard_deviations(
        Ks, [cameras[v]["R"] for v in views], [cameras[v]["t"] for v in views], X, rows[:, 0].astype(int),
        rows[:, 1].astype(int), rows[:, 2:])
    offset = np.linalg.norm(Ks[:, :2, 2] - np.median(Ks[:, :2, 2], axis=0), axis=1)
    return {"views": views, "sigma_px": sigma, "sd_px": sd.tolist(), "offset_px": offset.tolist(), "null": null}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="+")
    for path in parser.parse_args().results:
        found = precision(json.load(open(path)))
        print(f"## {path}: noise {found['sigma_px']:.3f} px, null space {found['null']} (the similarity's 7, and any the "
              "data leave free)")
        print("| view | principal point sd px | offset from the median px |\n|---|---|---|")
        for v, sd, offset in zip(found["views"], found["sd_px"], found["offset_px"]):
            print(f"| {v} | {sd:.2f} | {offset:.1f} |")


if __name__ == "__main__":
    main()
