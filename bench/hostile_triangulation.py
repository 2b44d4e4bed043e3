"""Claims the verifier refuses, on hostile random scenes: how many certified triangulation results
(batched and track by track) the per-item verifier does not accept.

Scenes of 12 random cameras (focal 100-3000 px, centres at scales 0.1-10, each camera multiplied
by 1, -1, 1e-6 or 1e6), 400 tracks of 2-9 views: points at distances 1 to 1e6 or at infinity,
noise 0.01-30 px, a gross outlier in some tracks, pixels clipped to 1e8. A certified result the
verifier refuses breaks the promise that a certified answer is checkable; this prints the count
and the verifier's reasons.

    .venv/bin/python -m bench.hostile_triangulation [--seeds 1,2,3] [--norms L2L2,L2L1,L1L1] [--tracks 400]

Nothing here asserts; tests/solvers hold the checked cases.
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import json

import numpy as np
from scipy.spatial.transform import Rotation

from geocert.verify import checks as verify
from geocert.solvers.core.geometry import normalised_cameras
from geocert.solvers.fractional.many_tracks import triangulate_many
from geocert.solvers.fractional.results import claim_of
from geocert.solvers.fractional.triangulation import TriangulationOptions, triangulate


def scene(seed: int, tracks: int, views: int = 12):
    rng = np.random.default_rng(seed)

    def camera():
        R = Rotation.random(random_state=rng).as_matrix()
        C = rng.normal(size=3) * rng.choice([0.1, 1, 10])
        K = np.diag([rng.uniform(100, 3000)] * 2 + [1.0])
        K[:2, 2] = rng.uniform(0, 1000, 2)
        return K @ np.hstack([R, (-R @ C)[:, None]]) * rng.choice([1, -1, 1e-6, 1e6])

    cameras = np.array([camera() for _ in range(views)])
    out = []
    for _ in range(tracks):
        k = int(rng.choice([2, 2, 3, 4, 6, 9]))
        chosen = sorted(rng.choice(views, k, replace=False).tolist())
        kind = rng.integers(0, 5)
        X = np.append(rng.normal(size=3) * rng.choice([1, 10, 1000, 1e6]), 1.0) if kind != 4 \
            else np.append(rng.normal(size=3), 0.0)
        x = np.einsum("vij,j->vi", cameras[chosen], X)
        with np.errstate(all="ignore"):
            p = x[:, :2] / x[:, 2:] + rng.normal(size=(k, 2)) * rng.choice([0.01, 1, 30])
        if kind == 3:
            p[0] += rng.normal(size=2) * 500
        out.append((chosen, np.clip(np.nan_to_num(p), -1e8, 1e8)))
    return cameras, out


def refused(cameras, views, points, result, options) -> str | None:
    claim = json.loads(json.dumps(claim_of(result, point=result.point, at_infinity=result.at_infinity)))
    try:
        verify.verify_arrays("triangulation", (normalised_cameras(cameras[views]), np.asarray(points, float)),
                             dataclasses.asdict(options), claim)
    except verify.Invalid as exc:
        return str(exc)
    return None


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", default="1,2,3")
    parser.add_argument("--norms", default="L2L2,L2L1,L1L1")
    parser.add_argument("--tracks", type=int, default=400)
    args = parser.parse_args()
    print("| seed | norm | solver | certified | refused by the verifier | reasons |")
    print("|---|---|---|---|---|---|")
    for seed in (int(s) for s in args.seeds.split(",")):
        cameras, tracks = scene(seed, args.tracks)
        for norm in args.norms.split(","):
            options = TriangulationOptions(norm=norm, certificate="full", time_limit_s=2.0, max_nodes=300)
            batched = triangulate_many(cameras, tracks, options)
            alone = [triangulate(cameras[views], points, options) for views, points in tracks]
            for name, results in (("batched", batched), ("track by track", alone)):
                reasons = collections.Counter()
                for (views, points), result in zip(tracks, results):
                    if result.certified and (why := refused(cameras, views, points, result, options)):
                        reasons[why.split(":")[0][:60]] += 1
                certified = sum(r.certified for r in results)
                print(f"| {seed} | {norm} | {name} | {certified} | {sum(reasons.values())} | "
                      f"{'; '.join(f'{k} ({v})' for k, v in reasons.items()) or '-'} |", flush=True)


if __name__ == "__main__":
    main()
