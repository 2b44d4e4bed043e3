"""Many tracks' results as a sequence of TrackResult, the convexity path's kept as columns.

The convexity path (fractional.convexity_path) certifies thousands of tracks in a few passes of
numpy; one TrackResult (and its LocalCertificate) a track cost about as much again. Here those
tracks stay arrays, ``LocalColumns``, and a track's TrackResult is made only when it is asked for
(by index or iteration), once: a caller that reads the columns (a count of certified tracks, a
result document built from arrays) never makes them. Every other track (searched, or not solved)
is held as the object its solver returned.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from geocert.formulations.fractional.results import LocalCertificate, TrackResult

SCOPE = "every point in front of every camera"


@dataclass
class LocalColumns:
    """The tracks certified at their local optimum by the convexity bound, row by row."""

    index: np.ndarray  # (k,) each row's track
    point: np.ndarray  # (k, 3)
    cost: np.ndarray  # (k,)
    lower_bound: np.ndarray  # (k,) the bound claimed
    tolerance: np.ndarray  # (k,)
    radius: np.ndarray  # (k,) the convexity proof's radius
    residuals: np.ndarray  # (m, 2) every row's residuals, row after row
    starts: np.ndarray  # (k + 1,) row j's residuals at starts[j]:starts[j + 1]
    proof: bool = True  # whether each certificate carries its proof ({"type": "convexity", "radius": R})
    elapsed_s: float = 0.0  # each row's share of the batched work's time
    # Each row's proven interval (LocalCertificate.sublevel), when they were computed: the cost
    # increase (k,), the ball's radius (k,) (nan where none is proven) and its bounds (k, 3, 2).
    sublevel_increase: np.ndarray | None = None
    sublevel_radius: np.ndarray | None = None
    sublevel_bounds: np.ndarray | None = None
    _sublevels: list | None = field(default=None, repr=False, compare=False)  # sublevels(), once made

    @property
    def gap(self) -> np.ndarray:
        return self.cost - self.lower_bound

    def sublevel(self, row: int) -> dict | None:
        """Row ``row``'s proven interval, as LocalCertificate.sublevel states it (None: none)."""
        if self.sublevel_radius is None or not np.isfinite(self.sublevel_radius[row]):
            return None
        return {"cost_increase": float(self.sublevel_increase[row]), "radius": float(self.sublevel_radius[row]),
                "intervals": self.sublevel_bounds[row].tolist()}

    def sublevels(self) -> list[dict | None]:
        """Every row's sublevel, made once for all rows (one tolist a column)."""
        if self._sublevels is None:
            if self.sublevel_radius is None:
                self._sublevels = [None] * len(self.index)
            else:
                proven = np.isfinite(self.sublevel_radius)
                self._sublevels = [
                    {"cost_increase": increase, "radius": radius, "intervals": bounds} if good else None
                    for good, increase, radius, bounds in zip(proven.tolist(), self.sublevel_increase.tolist(),
                                                              self.sublevel_radius.tolist(),
                                                              self.sublevel_bounds.tolist())]
        return self._sublevels

    def set_sublevel(self, row: int, increase: float, radius: float, bounds: np.ndarray) -> None:
        """Row ``row``'s proven interval replaced (radius nan: none)."""
        self.sublevel_increase[row], self.sublevel_radius[row], self.sublevel_bounds[row] = increase, radius, bounds
        self._sublevels = None

    def result(self, row: int) -> TrackResult:
        """Row ``row`` as the TrackResult the convexity path certifies."""
        cost, lower, radius = float(self.cost[row]), float(self.lower_bound[row]), float(self.radius[row])
        sublevel = self.sublevel(row)
        proof = {"type": "convexity", "radius": radius} if self.proof else None
        if proof is not None and sublevel is not None:
            proof["sublevel"] = sublevel
        return TrackResult(status="optimal", certified=True, cost=cost, lower_bound=lower, gap=cost - lower,
                           nodes=0, elapsed_s=self.elapsed_s, point=self.point[row].tolist(),
                           residuals=self.residuals[self.starts[row]:self.starts[row + 1]].tolist(),
                           certificate=LocalCertificate(SCOPE, float(self.tolerance[row]), radius, proof,
                                                        sublevel=sublevel))


class TrackResults(Sequence):
    """One entry per track, in order: a TrackResult, or None for a track not (yet) solved.
    A row of ``local`` is made into a TrackResult on first access and from then on held as that
    object (a caller may change the object it was given, as with a list): the columns describe
    only the tracks still in them (in_columns)."""

    def __init__(self, count: int, local: LocalColumns | None = None):
        self._count = count
        self.objects: dict[int, TrackResult] = {}  # the tracks held (or already made) as objects
        self.local = local
        self._row = np.full(count, -1, dtype=np.int64)  # each track's row of ``local``, -1 for none
        if local is not None:
            self._row[local.index] = np.arange(len(local.index))

    def __len__(self) -> int:
        return self._count

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(self._count))]
        i = range(self._count)[i]  # negative indices, and IndexError past the end
        found = self.objects.get(i)
        if found is None and self._row[i] >= 0:
            found = self.objects[i] = self.local.result(int(self._row[i]))
            self._row[i] = -1
        return found

    def __setitem__(self, i: int, result: TrackResult | None) -> None:
        i = range(self._count)[i]
        self._row[i] = -1
        if result is None:
            self.objects.pop(i, None)
        else:
            self.objects[i] = result

    def row(self, i: int) -> int:
        """Track ``i``'s row of ``local``, -1 when it is held as an object (or has no result)."""
        return int(self._row[i])

    def in_columns(self) -> np.ndarray:
        """Whether each track is (still) a row of ``local``, not an object: (T,) bool."""
        return self._row >= 0

    def unsolved(self) -> list[int]:
        """The tracks with no result, in order."""
        missing = self._row < 0
        missing[list(self.objects)] = False
        return np.flatnonzero(missing).tolist()

    def certified_count(self) -> int:
        """How many tracks are certified (every row of the columns is), without making objects."""
        rows = self._row >= 0
        return int(rows.sum()) + sum(1 for r in self.objects.values() if r.certified)


def solutions(results: Sequence) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each track's finite point, cost and lower bound, read without making the columns' rows
    into objects: (point (T, 3), finite (T,) whether the track has a point not at infinity,
    cost (T,), lower (T,)), nan where a track has none."""
    T = len(results)
    point = np.full((T, 3), np.nan)
    cost, lower = np.full(T, np.nan), np.full(T, np.nan)
    finite = np.zeros(T, dtype=bool)
    if isinstance(results, TrackResults):
        local, rows = results.local, results.in_columns()
        if local is not None and rows.any():
            row = results._row[rows]
            point[rows], cost[rows], lower[rows] = local.point[row], local.cost[row], local.lower_bound[row]
            finite[rows] = True
        others = results.objects.items()
    else:
        others = enumerate(results)
    for i, result in others:
        if result is None:
            continue
        cost[i] = np.nan if result.cost is None else result.cost
        # a result not certified states no lower bound (documents.outcome_document): its estimate reads none
        lower[i] = result.lower_bound if result.certified and result.lower_bound is not None else np.nan
        if result.point is not None and not result.at_infinity:
            point[i], finite[i] = result.point, True
    return point, finite, cost, lower


def sublevels(results: Sequence) -> list[dict | None]:
    """Each track's proven interval (its certificate's sublevel, None where none), read without
    making the columns' rows into objects."""
    out: list[dict | None] = [None] * len(results)
    if isinstance(results, TrackResults):
        local, rows = results.local, results.in_columns()
        if local is not None and rows.any():
            found = local.sublevels()
            for i, row in zip(np.flatnonzero(rows).tolist(), results._row[rows].tolist()):
                out[i] = found[row]
        others = results.objects.items()
    else:
        others = enumerate(results)
    for i, result in others:
        if result is not None:
            out[i] = certified_sublevel(result)
    return out


def certified_sublevel(result) -> dict | None:
    """A result's proven interval where its claim stands: a search may prove one and the result be
    decertified after it (its bound not the data's problem's, items.UNDISCOUNTABLE), and the
    verifier reads a sublevel only from a certified claim's proof, so an uncertified track whose
    estimate said "proven" was refused on its writer's own machine."""
    return getattr(result.certificate, "sublevel", None) if result.certified else None
