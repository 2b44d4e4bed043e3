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

from geocert.solvers.fractional.many_tracks import triangulate_many
from geocert.solvers.fractional.triangulation import TriangulationOptions, triangulate
from testing.hostile_triangulation import refused, scene


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
