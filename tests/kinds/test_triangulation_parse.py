"""The triangulation kind's parse: its checks made on every track at once (tracks_in_bulk) read
the tracks as the per-track loop reads them, and refuse whatever that loop refuses, which then
names the entry."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from geocert.kinds import triangulation
from geocert.kinds.triangulation import KIND, tracks_in_bulk
from geocert.core.geometry import InputError


def request_data(rng, tracks: int = 30, cameras: int = 6) -> dict:
    entries = []
    for _ in range(tracks):
        views = sorted(rng.choice(cameras, size=int(rng.integers(2, cameras + 1)), replace=False).tolist())
        entries.append({"views": views, "points": (rng.normal(size=(len(views), 2)) * 300).tolist()})
    entries[0]["points"][0] = [3, 4]  # ints are numbers too
    return {"cameras": [[[800.0, 0, 320, float(i)], [0, 800.0, 240, 0], [0, 0, 1, 0]] for i in range(cameras)],
            "tracks": entries}


def per_track(data: dict, items=None):
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(triangulation, "tracks_in_bulk", lambda *args: None)
        return KIND.parse(data, items)


@pytest.mark.parametrize("items", [None, range(5, 17)])
def test_in_bulk_the_tracks_are_the_per_track_loops(items):
    data = request_data(np.random.default_rng(3))
    chosen = items if items is not None else range(len(data["tracks"]))
    assert tracks_in_bulk(data["tracks"], chosen, len(data["cameras"])) is not None
    ours, theirs = KIND.parse(data, items), per_track(data, items)
    for mine, other in zip(ours.tracks, theirs.tracks):
        assert (mine is None) == (other is None)
        if mine is not None:
            assert mine[0] == other[0] and np.array_equal(mine[1], other[1]) and mine[1].shape == other[1].shape


BAD = {
    "a track not an object": lambda t: t.__setitem__(3, [1, 2]),
    "no views": lambda t: t[3].pop("views"),
    "a view index a float": lambda t: t[3]["views"].__setitem__(0, 1.0),
    "a view index a bool": lambda t: t[3]["views"].__setitem__(0, True),
    "a view out of range": lambda t: t[3]["views"].__setitem__(0, 6),
    "a negative view": lambda t: t[3]["views"].__setitem__(0, -1),
    "a view index beyond int64": lambda t: t[3]["views"].__setitem__(0, 10 ** 25),  # was a 500 (OverflowError)
    "a view twice": lambda t: t[3].update(views=[1, 1], points=[[1.0, 2.0], [3.0, 4.0]]),
    "one view": lambda t: t[3].update(views=[1], points=[[1.0, 2.0]]),
    "fewer points than views": lambda t: t[3]["points"].pop(),
    "a point of three numbers": lambda t: t[3]["points"].__setitem__(0, [1.0, 2.0, 3.0]),
    "a coordinate a string": lambda t: t[3]["points"].__setitem__(0, [1.0, "2"]),
    "a coordinate a bool": lambda t: t[3]["points"].__setitem__(0, [1.0, False]),
    "a coordinate not finite": lambda t: t[3]["points"].__setitem__(0, [1.0, float("nan")]),
    "a coordinate beyond the limit": lambda t: t[3]["points"].__setitem__(0, [1.0, 2e9]),
    "a huge integer coordinate": lambda t: t[3]["points"].__setitem__(0, [1.0, 10 ** 400]),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_what_the_loop_refuses_the_bulk_check_leaves_to_it(name):
    data = request_data(np.random.default_rng(4))
    data["tracks"][3] = {"views": [0, 1, 2], "points": [[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]]}
    BAD[name](data["tracks"])
    assert tracks_in_bulk(data["tracks"], range(len(data["tracks"])), len(data["cameras"])) is None
    with pytest.raises(InputError) as raised:
        KIND.parse(copy.deepcopy(data))
    assert raised.value.field.startswith("data/tracks/3")
