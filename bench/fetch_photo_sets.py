"""Fetch the public photo sets the benches read (issue 35) into the data root, each file checked
against testing/photo_sets_manifest.json (the logic, sources, credits and licences:
testing/fetch_photo_sets.py).

    .venv/bin/python -m bench.fetch_photo_sets [--sets templeRing,templeSparseRing,sceaux,kittiStraight,kittiTurn]
        [--root DIR] [--source middlebury=URL] [--source sceaux=GIT] [--source kitti=GIT]
        [--source visual_hull=GIT]

The root defaults to $GEOCERT_BENCH_DATA, else bench-data beside the checkout (where
bench/reconstruction_vs_colmap.py reads, which also fetches a missing set when run with --fetch).
A source defaults to $GEOCERT_FETCH_MIDDLEBURY, $GEOCERT_FETCH_SCEAUX, $GEOCERT_FETCH_KITTI (and the
others testing/fetch_photo_sets.py names), else the public address; templeSparseRing comes from a
git copy of Middlebury's files (visual_hull) where Middlebury's zip cannot be downloaded. dinoSparseRing and the Oxford Corridor are not fetched.
"""

from __future__ import annotations

import argparse
import sys

from testing import fetch_photo_sets, photo_sets


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", default=",".join(fetch_photo_sets.SETS),
                        help=f"comma-separated, of {', '.join(fetch_photo_sets.SETS)}")
    parser.add_argument("--root", default=None, help="data root (default $GEOCERT_BENCH_DATA, else bench-data "
                        "beside the checkout)")
    parser.add_argument("--source", action="append", default=[], metavar="NAME=URL",
                        help=f"a source's address, NAME one of {', '.join(fetch_photo_sets.DEFAULT_SOURCES)}")
    args = parser.parse_args(argv)
    sources = {}
    for item in args.source:
        name, _, url = item.partition("=")
        if name not in fetch_photo_sets.DEFAULT_SOURCES or not url:
            parser.error(f"--source {item!r}: NAME=URL, NAME one of {', '.join(fetch_photo_sets.DEFAULT_SOURCES)}")
        sources[name] = url
    root = photo_sets.data_root(args.root)
    failed = 0
    for key in args.sets.split(","):
        try:
            fetch_photo_sets.fetch(key, root, sources)
        except fetch_photo_sets.FetchError as error:
            print(f"{key}: {error}", file=sys.stderr)
            failed += 1
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
