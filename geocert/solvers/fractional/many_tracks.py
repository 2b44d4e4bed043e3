"""Many triangulation tracks at once: for each, what ``triangulate`` returns, with the
Python-level work shared by the tracks of a group (same number of views).

One track's solve is some 1,500 small Python-level calls around little arithmetic (chart, DLT,
local refinement, the root region's 2d small SOCPs, the root node's relaxation); 99.5% of the
Dinosaur's tracks close at the root node. Here each stage runs on stacked arrays:

* search.prepare for a group: the charts (stacked.chart_arrays, the verifier's stacked
  Chart.build), the DLT starts, a batched Levenberg-Marquardt on the L2L2 residuals (under
  L2L1 and L1L1 the per-track refinement of search.prepare), the scaling, and the branched
  functionals (search.branch_directions' greedy choice, vectorised);
* the root region (search.root_region and prove_root; under L2L1 and L1L1 search.root_region
  itself, track by track, see _batched): under L2L2 the 2d bounds of every track by one
  batched log-barrier method over tracks of nearby lengths, instead of 2d Clarabel solves;
  each bound is the safe bound of its own dual vector (cones.safe_lower_bound's, for all
  tracks at once), over the claimed box prove_root claims, so an inaccurate barrier can only
  make a looser bound, or none (the track is then solved alone);
* the root node (bnb.branch_and_bound's first node, bounded as BoxProblem._bound bounds it):
  the relaxations assembled for a group (stacked.leaf_relaxations, Relaxation.conic_data row
  for row), each solved by Clarabel with BoxProblem's settings, each bound the safe bound of
  its dual; the relaxation's point tried as the incumbent as bnb tries it.

A track whose root closes the gap ends there with the certificate of a one-node search. Any
other track (not closed at the root, max_residual given, more than search.ROOT_SUBSET views,
a chart this path does not build: a view's depth row parallel to the reference's or a camera
centre at infinity, a start outside the domain, a root region not proven, ...) is solved by
``triangulate`` itself.

Why: on the Dinosaur's 4,983 tracks under L2L2, in chunks of 500, this costs about what OpenCV's
DLT + LM costs a track, against some four times that for ``triangulate`` track by track
(bench/triangulation.py; docs/benchmarks.md has the current figures). A batched barrier for the
root relaxation too was tried and not kept: its ~50 Newton passes of stacked 7x7 to 31x31 systems
cost more than Clarabel's solves.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections import defaultdict
from typing import Callable

import numpy as np

from geocert.core.bnb import Box, Progress
from geocert.core.certificates import LeafProof, RootProof, SearchProof, encode, residual_rounding
from geocert.core.conic import ConicStatus, ReusableConicProgram
from geocert.core.cones import ConeSpec
from geocert.core.geometry import cost_roundings, normalised_cameras
from geocert.formulations.fractional import stacked
from geocert.formulations.fractional.charts import Chart
from geocert.formulations.fractional.columns import TrackResults
from geocert.formulations.fractional.convexity_path import certify_tracks
from geocert.formulations.fractional.options import TriangulationOptions
from geocert.formulations.fractional.relaxation import FractionalProgram, cost_unit, gamma_for
from geocert.formulations.fractional.results import SearchCertificate, TrackResult, claim_of
from geocert.solvers.fractional.search import (MAX_SCALE, ROOT_SUBSET, branch_directions, depth_subspace,
                                               local_refine, recomputed_status, root_region)
from geocert.formulations.fractional.items import PROGRAM_REFUSED, UNDISCOUNTABLE, TrackItem, refused_by_verifier
from geocert.formulations.fractional.proof import SOLVER_DISCOUNT_FACTOR, track_uncertainty
from geocert.solvers.fractional.triangulation import track_result, triangulate
from geocert.core import barrier, self_check

D = 3
SCOPE = "every point in front of every camera"
MAX_GROUP = 256  # tracks stacked in one group's arrays
LEAF_MARGIN = 1e-8  # a root node's claimed bound below its computed safe bound (relative, + absolute)
# Tracks of the batched work between two calls of the caller's callback (which may stop it): each
# is a few milliseconds of per-track work under L2L1 and L1L1 (two local refinements, the root
# region's 2d conic solves, the root node's), so a stop is seen within some tens of milliseconds.
CHECK_EVERY = 8
STOPPED_BEFORE = "the job was cancelled before this track started"


class _Stopped(Exception):
    """The callback asked to stop during the batched work."""


class _Watch:
    """The caller's callback over a batch: called every CHECK_EVERY tracks of the batched work
    (with no bounds: a batch's figures come with its items) and between the nodes of the
    searches of the tracks solved alone; once it has asked to stop, it stays stopped."""

    def __init__(self, callback: Callable[[Progress], bool | None] | None, started: float):
        self.callback, self.started = callback, started
        self.stopped = False
        self.count = 0

    def tick(self, tracks: int = 1) -> None:
        """``tracks`` more tracks of batched work done: the callback every CHECK_EVERY, and
        _Stopped raised once it asks to stop."""
        if self.callback is None:
            return
        self.count += tracks
        if self.count >= CHECK_EVERY:
            self.count = 0
            if self.search(Progress(0, 0, -math.inf, math.inf, math.inf, math.inf, time.perf_counter() - self.started)):
                raise _Stopped

    def search(self, progress: Progress) -> bool:
        """The callback a search of a track solved alone is given."""
        if not self.stopped and self.callback is not None and self.callback(progress):
            self.stopped = True
        return self.stopped


def triangulate_many(cameras: np.ndarray, tracks: list[tuple[list[int], np.ndarray]],
                     options: TriangulationOptions | None = None,
                     callback: Callable[[Progress], bool | None] | None = None,
                     deadline: float | None = None, not_started: str = "not started: past the deadline",
                     stop_ends_batch: bool = False) -> TrackResults:
    """Certified global optimum of every track: ``cameras`` (N, 3, 4) of the whole scene,
    ``tracks`` a list of ``(views, points)`` with ``views`` indices into ``cameras`` and
    ``points`` (len(views), 2). Returns one TrackResult per track, in order, as a TrackResults
    sequence (fractional.columns): the tracks the convexity path certifies are kept as columns,
    each made into its TrackResult when it is read.

    Inputs are taken as validated (as the triangulation kind validates them: finite numbers,
    view indices in range, no view twice in a track, at least two views).

    Under L2L2 with no max_residual, a track first goes through the convexity path
    (convexity_path.certify_tracks): certified at its local optimum by the convexity bound, with
    a LocalCertificate and nodes 0 (what ``triangulate`` would certify by a search, within the
    tolerance: the bound holds for every point of the scope). The contract below is that of
    every other track.

    Contract: each result is what ``triangulate(cameras[views], points, options)`` returns
    for that track in its status, its certified flag and the form of its certificate (a
    SearchCertificate with the same scope, reference view and number of functionals; with
    ``options.certificate == "full"`` a proof that geocert.verify.checks and the stacked
    verifier accept: the root region's proof and one leaf closed by a dual vector, every
    bound the safe bound of its own dual, recomputed by the verifier). What may differ:

    * the point, by what two local refinements leave: its cost is triangulate's within 1e-9
      relative, or lower (measured on 300 Dinosaur tracks of 2 to 10 views: at most 1.5e-10
      higher under any norm; under L2L2 the batched refinement runs to convergence, under L2L1
      and L1L1 the refinements and the root region are triangulate's own, see _batched);
    * the lower bound and the gap, by the accuracy of the solves (always proven, and within
      the tolerance whenever certified);
    * ``nodes`` (1 where the root closed), the certificate's box and tolerance in their last
      digits, and ``elapsed_s`` (the batched work's time shared by the tracks it closed).

    Tracks the batched path does not close are solved by ``triangulate`` itself, so every
    status it returns is possible. ``callback`` is called between the nodes of those searches;
    once it returns True, the search running stops (``cancelled``, its best point). With
    ``stop_ends_batch`` (a job's batch, where a stop is a cancel) it is also called every
    CHECK_EVERY tracks of the batched work (a Progress with no bounds), and once it has asked to
    stop no track is started: every track not finished reads ``cancelled``, uncertified and
    without a point (STOPPED_BEFORE). Without it (a reconstruction's structure stage, which keeps
    a stopped track's best point) the batched work runs to its end and each track left is still
    prepared, its search stopping at its first node. ``deadline`` (a ``time.monotonic()`` value)
    is one clock the batch shares: each of those searches stops by it (its time_limit_s no longer than what is
    left, so it ends ``time_limit`` with its best point), and a track not started by then reads
    ``time_limit`` with reason ``not_started``, uncertified and without a point. The work before
    them (the convexity path, the stacked roots) is bounded by the batch's size and not timed.
    With GEOCERT_SELF_VERIFY=1 every certified result is
    checked by the verifier, as ``triangulate`` checks its own; the proof is returned only
    with ``options.certificate == "full"``.
    """
    options = options or TriangulationOptions()
    checking = self_check.enabled()
    run = dataclasses.replace(options, certificate="full") if checking else options
    cameras = normalised_cameras(cameras)
    started = time.perf_counter()
    watch = _Watch(callback if stop_ends_batch else None, started)
    results = TrackResults(len(tracks))
    try:
        # Under L2L2 most tracks are certified at their local optimum, without a search (kept
        # as columns: no object a track).
        results = certify_tracks(cameras, tracks, run)
    except (ArithmeticError, ValueError, np.linalg.LinAlgError):
        pass  # data this path does not handle: every track goes on to the search
    groups: dict[int, list[int]] = defaultdict(list)
    for i in results.unsolved():
        groups[len(tracks[i][0])].append(i)
    if run.max_residual is None:  # with a scope limit every track is solved alone (rare, not stacked)
        try:
            _batched(cameras, tracks, groups, run, results, watch)
        except _Stopped:
            pass  # what it finished stands; the rest read cancelled below
        except (ArithmeticError, ValueError, np.linalg.LinAlgError):
            # Data this path does not handle (e.g. an SVD that does not converge on non-finite
            # numbers): what it finished stands, every other track is solved alone.
            pass
    searched = dict(results.objects)  # the batched search's results (no column made into one yet)
    local = results.local
    share = (time.perf_counter() - started) / max(1, len(searched) + (len(local.index) if local else 0))
    if local is not None:
        local.elapsed_s = share
    for result in searched.values():
        result.elapsed_s = share
    alone = results.unsolved()
    for i in alone:
        # triangulate self-checks its own results (and keeps the proof only when asked for).
        # ``callback`` sees (and may stop) these searches; once stopped, with stop_ends_batch, no
        # track is started.
        if watch.stopped:
            results[i] = TrackResult("cancelled", False, reason=STOPPED_BEFORE)
            continue
        left = math.inf if deadline is None else deadline - time.monotonic()
        if left <= 0:
            results[i] = TrackResult("time_limit", False, reason=not_started)
            continue
        views, points = tracks[i]
        run_alone = options if left >= options.time_limit_s else dataclasses.replace(options, time_limit_s=left)
        results[i] = triangulate(cameras[list(views)], points, run_alone, watch.search if stop_ends_batch else callback)
    if checking:  # the columns' rows checked as the objects they would make (not kept)
        rows = [] if local is None else [(int(i), local.result(row)) for row, i in enumerate(local.index)]
        for i, result in [*searched.items(), *rows]:
            views, points = tracks[i]
            if result.certified:
                self_check.check("triangulation", (cameras[list(views)], np.asarray(points, dtype=float)),
                           dataclasses.asdict(run),
                           claim_of(result, point=result.point, at_infinity=result.at_infinity))
    if options.certificate != "full":
        if local is not None:
            local.proof = False
        alone = set(alone)
        for i, result in results.objects.items():
            if i not in alone and result.certificate is not None:
                result.certificate.proof = None
    return results


def _batched(cameras, tracks, groups: dict, options: TriangulationOptions, results: list, watch: _Watch) -> None:
    """Fill ``results`` with the tracks this path closes: search.prepare per group, the root
    regions of every track, then the root nodes per (views, branched functionals). ``watch``
    is told of the tracks done as the work goes (it raises _Stopped when asked to stop)."""
    entries: list[Entry] = []
    charted = []  # (members, the group's charts and starts)
    for n, members in groups.items():
        if n > ROOT_SUBSET:
            continue  # search.root_region bounds these by a subset of their views
        for start in range(0, len(members), MAX_GROUP):
            chunk = members[start:start + MAX_GROUP]
            group = _chart_group(cameras, [tracks[i] for i in chunk], n)
            if group is not None:
                charted.append((chunk, group))
            watch.tick(len(chunk))
    if options.norm == "L2L2":
        _refine_groups([group for _, group in charted])
    for chunk, group in charted:
        ended, ready = _prepare_group(group, options, watch)
        for i, result in zip(chunk, ended):
            results[i] = result
        for entry in ready:
            entry.index = chunk[entry.index]
            entries.append(entry)
    if options.norm == "L2L2":
        proofs = _root_regions(entries, watch)
    else:
        # search.root_region itself (2d Clarabel solves a track): under L2L1 and L1L1 the root
        # relaxation's point, refined where it beats the incumbent, lands on the cost's kinks,
        # where a root box differing in its last digits moves the point returned (measured: a
        # cost 4e-8 higher than triangulate's on one track of 300 with the barrier's boxes).
        proofs = []
        for entry in entries:
            proofs.append(root_region(entry.chart.program, entry.B, entry.gamma)[2])
            watch.tick()
    by_shape: dict[tuple[int, int], list] = defaultdict(list)
    for entry, proof in zip(entries, proofs):
        if proof is not None:
            by_shape[(len(entry.points), len(entry.B))].append((entry, proof))
    for (n, k), closing in by_shape.items():
        for start in range(0, len(closing), MAX_GROUP):
            for index, result in _root_nodes(closing[start:start + MAX_GROUP], k, options, watch):
                results[index] = result


def _chart_group(all_cameras: np.ndarray, tracks: list, n: int) -> dict | None:
    """The charts and DLT starts of one group's tracks (n views each), None for data this path
    does not take."""
    G = len(tracks)
    cams = all_cameras[np.array([list(views) for views, _ in tracks])]  # (G, n, 3, 4)
    points = np.array([np.asarray(p, dtype=float) for _, p in tracks])  # (G, n, 2)
    if n < 2 or points.shape != (G, n, 2) or not np.all(np.isfinite(points)):
        return None
    with np.errstate(all="ignore"):
        num, den, T, reference, ok = stacked.chart_arrays(cams, points)
        ok &= np.all(np.isfinite(num), axis=(1, 2, 3)) & np.all(np.isfinite(den), axis=(1, 2))
        v0, ok_start = _dlt(num)
    return {"cams": cams, "points": points, "num": num, "den": den, "T": T, "reference": reference,
            "ok": ok & ok_start, "v0": v0}


def _refine_groups(groups: list[dict]) -> None:
    """_refine_l2l2 on the starts of every group, groups of nearby lengths together (views
    padded with a residual of 0 and a depth of 1: no cost, no derivative)."""
    sizes = [group["num"].shape[1] for group in groups]
    # Buckets of whole groups, by length, shortest first (as _buckets forms them for tracks).
    order = sorted(range(len(groups)), key=lambda g: sizes[g])
    bucket: list[int] = []
    for position, g in enumerate(order):
        bucket.append(g)
        count = sum(len(groups[h]["num"]) for h in bucket)
        following = sizes[order[position + 1]] if position + 1 < len(order) else None
        if following is None or count >= MIN_BUCKET or following > 1.5 * sizes[bucket[0]]:
            _refine_padded([groups[h] for h in bucket])
            bucket = []


def _refine_padded(groups: list[dict]) -> None:
    n = max(group["num"].shape[1] for group in groups)
    num, den, linear, v0, ok = [], [], [], [], []
    for group in groups:
        G, own = group["num"].shape[:2]
        padded_num = np.zeros((G, n, 2, 4))
        padded_den = np.zeros((G, n, 4))
        padded_den[:, :, 3] = 1.0
        padded_num[:, :own], padded_den[:, :own] = group["num"], group["den"]
        num.append(padded_num), den.append(padded_den), linear.append(group["T"][:, 3])
        v0.append(group["v0"]), ok.append(group["ok"])
    with np.errstate(all="ignore"):
        v, good = _refine_l2l2(np.concatenate(num), np.concatenate(den), np.concatenate(linear),
                               np.concatenate(v0), np.concatenate(ok))
    start = 0
    for group in groups:
        G = len(group["num"])
        group["v0"], group["ok"] = v[start:start + G], good[start:start + G]
        start += G


def _prepare_group(group: dict, options: TriangulationOptions, watch: _Watch):
    """search.prepare for the tracks of one group (n views each) from their charts and starts
    (refined under L2L2): (results of the tracks that end here, None for the rest; the Entries
    of the tracks ready for a root region)."""
    cams, points, num, den, T = group["cams"], group["points"], group["num"], group["den"], group["T"]
    reference, ok, v0 = group["reference"], group["ok"].copy(), group["v0"].copy()
    G, n = den.shape[:2]
    out: list = [None] * G
    norm = options.norm
    exact = np.zeros((G, n), dtype=bool)
    exact[np.arange(G), reference] = True
    cost0 = _l2l2_cost(num, den, T[:, 3], v0)[0]
    ok &= np.isfinite(cost0)
    programs: dict[int, FractionalProgram] = {}
    if norm != "L2L2":
        # Refined as search.prepare refines them, per track (scipy's LM under L2L2, then under the
        # norm): on these costs' kinks a refinement converged further stops elsewhere, at a cost
        # that can differ in the 8th digit.
        for g in np.flatnonzero(ok):
            programs[g] = FractionalProgram(num[g].copy(), den[g].copy(), exact[g], T[g, 3][None, :].copy(), norm)
            start, _ = local_refine(programs[g], v0[g], "L2L2")
            v0[g], cost0[g] = local_refine(programs[g], start)
            watch.tick()
        ok &= np.isfinite(cost0)
    trivial = ok & (cost0 <= options.abs_gap)  # within tolerance of the trivial bound 0
    for g in np.flatnonzero(trivial):
        program = programs.get(g) or FractionalProgram(num[g].copy(), den[g].copy(), exact[g], T[g, 3][None, :].copy(),
                                                       norm)
        chart = Chart(program, T[g], int(reference[g]), False)
        out[g] = track_result(chart, cams[g], points[g], v0[g], options, "optimal", 0.0, 0, None)
    ok &= ~trivial
    with np.errstate(all="ignore"):
        factor = np.minimum(MAX_SCALE, 1.0 / np.sqrt(cost0) if norm == "L2L2" else 1.0 / cost0)
        scaled = num * factor[:, None, None, None]
        upper = _costs(scaled, den, T[:, 3], v0, norm)
    ok &= np.isfinite(upper)
    B = _branching(den, exact, ok)
    entries = []
    for g in np.flatnonzero(ok):
        program = FractionalProgram(scaled[g], den[g].copy(), exact[g], T[g, 3][None, :].copy(), norm)
        chart = Chart(program, T[g], int(reference[g]), False)
        entries.append(Entry(g, chart, v0[g], float(factor[g]), float(upper[g]), gamma_for(float(upper[g]), norm),
                             B[g], cams[g], points[g]))
    return out, entries


@dataclasses.dataclass
class Entry:
    """A track ready for its root region: search.prepare's state after the scaling."""

    index: int  # in its group, then in the batch
    chart: Chart  # its program scaled (residuals times ``factor``)
    v0: np.ndarray  # the incumbent (chart coordinates)
    factor: float
    upper: float  # the incumbent's scaled cost
    gamma: float
    B: np.ndarray  # the branched functionals (search.branch_directions)
    cams: np.ndarray
    points: np.ndarray


def _costs(num, den, linear, v, norm: str) -> np.ndarray:
    """FractionalProgram.cost of every track at ``v`` (inf outside the domain)."""
    V = np.concatenate([v, np.ones((len(v), 1))], axis=1)
    g = np.einsum("gnk,gk->gn", den, V)
    r = np.einsum("gnmk,gk->gnm", num, V) / g[..., None]
    lin = np.einsum("gk,gk->g", linear, V)
    inside = np.all(g > 0, axis=1) & ((lin >= 0) | (lin >= -1e-12 * np.linalg.norm(linear, axis=1)
                                                    * np.linalg.norm(V, axis=1)))
    if norm == "L2L2":
        cost = np.sum(r * r, axis=(1, 2))
    elif norm == "L2L1":
        cost = np.sum(np.sqrt(np.sum(r * r, axis=2)), axis=1)
    else:
        cost = np.sum(np.abs(r), axis=(1, 2))
    cost = np.where(inside, cost, np.inf)
    return np.where(np.isfinite(cost), cost, np.inf)


def _branching(den: np.ndarray, exact: np.ndarray, ok: np.ndarray) -> list:
    """search.branch_directions(program, depth_subspace(program)) for every track: the
    depth subspace's rank k, then k best-conditioned depth gradients by greedy Gram-Schmidt.
    Tracks where the greedy choice stops short (a gradient below 0.25 after projection, or
    none left) take search's own functions."""
    G, n = exact.shape
    gradients = den[~exact].reshape(G, n - 1, 4)[..., :3]
    out: list = [None] * G
    with np.errstate(all="ignore"):
        singular = np.linalg.svd(gradients, compute_uv=False)
        rank = np.sum(singular > 1e-12 * np.maximum(1.0, singular[:, :1]), axis=1)
        sizes = np.linalg.norm(gradients, axis=2)
        candidates = gradients / np.where(sizes > 0, sizes, 1.0)[..., None]
        residuals = candidates.copy()
        used = ~(sizes > 0)
        chosen = np.zeros((G, 3, 3))
        fine = ok & (rank > 0)
        every = np.arange(G)
        for j in range(int(rank.max(initial=0))):
            going = j < rank
            norms = np.where(used, -1.0, np.linalg.norm(residuals, axis=2))
            best = np.argmax(norms, axis=1)
            top = norms[every, best]
            fine &= ~going | (top >= 0.25)
            chosen[every, j] = candidates[every, best]
            basis = residuals[every, best] / np.where(top > 0, top, 1.0)[:, None]
            used[every, best] |= going
            residuals = residuals - np.einsum("gi,gj->gij", np.einsum("gij,gj->gi", residuals, basis), basis)
    for g in range(G):
        if not ok[g]:
            continue
        if fine[g]:
            out[g] = chosen[g, :rank[g]].copy()
        else:
            program = FractionalProgram(np.zeros((n, 2, 4)), den[g], exact[g], np.zeros((0, 4)), "L2L2")
            out[g] = branch_directions(program, depth_subspace(program))
    return out


# --- starts ---------------------------------------------------------------------------------

def _dlt(num: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Chart.dlt for every track: (v, ok)."""
    G = len(num)
    rows = num.reshape(G, -1, 4)
    rows = rows / np.linalg.norm(rows, axis=2, keepdims=True)
    Y = np.linalg.svd(rows)[2][:, -1]
    ok = np.abs(Y[:, 3]) >= 1e-14 * np.linalg.norm(Y, axis=1)
    ok &= np.all(np.isfinite(Y), axis=1)
    return Y[:, :3] / np.where(ok, Y[:, 3], 1.0)[:, None], ok


def _l2l2_cost(num, den, linear, v):
    """The programs' L2L2 costs at ``v`` (inf outside the domain), and the residuals."""
    V = np.concatenate([v, np.ones((len(v), 1))], axis=1)
    g = np.einsum("gnk,gk->gn", den, V)
    r = np.einsum("gnmk,gk->gnm", num, V) / g[..., None]
    lin = np.einsum("gk,gk->g", linear, V)
    inside = np.all(g > 0, axis=1) & (lin >= -1e-12 * np.linalg.norm(linear, axis=1) * np.linalg.norm(V, axis=1))
    cost = np.where(inside, np.sum(r * r, axis=(1, 2)), np.inf)
    return np.where(np.isfinite(cost), cost, np.inf), r, g, V


def _refine_l2l2(num, den, linear, v, ok, iterations: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """A batched Levenberg-Marquardt on every track's L2L2 residuals from ``v``, never moving a
    track to a worse or infeasible point; ok false where the start is not in the domain. A track
    stops once a step lowers its cost by less than 1e-15 relative, a step is below round-off, or
    its damping has grown past 1e8 (no step lowers the cost)."""
    cost, r, g, _ = _l2l2_cost(num, den, linear, v)
    ok = ok & np.isfinite(cost)
    v = v.copy()
    lam = np.full(len(v), 1e-3)
    active = ok.copy()
    for _ in range(iterations):
        sel = np.flatnonzero(active)
        if not len(sel):
            break
        ns, ds, rs, gs, vs = num[sel], den[sel], r[sel], g[sel], v[sel]
        # J = d r / d v = (num[..., :3] - r * den[..., :3]) / g
        J = ((ns[..., :3] - rs[..., None] * ds[:, :, None, :3]) / gs[..., None, None]).reshape(len(sel), -1, 3)
        JtJ = np.einsum("gra,grb->gab", J, J)
        Jtr = np.einsum("gra,gr->ga", J, rs.reshape(len(sel), -1))
        damped = JtJ + lam[sel, None, None] * (np.eye(3) * (np.einsum("gaa->ga", JtJ)[:, None, :] + 1e-12))
        try:
            step = -np.linalg.solve(damped, Jtr[..., None])[..., 0]
        except np.linalg.LinAlgError:
            break
        trial = vs + step
        trial_cost, trial_r, trial_g, _ = _l2l2_cost(ns, ds, linear[sel], trial)
        better = np.isfinite(trial_cost) & (trial_cost < cost[sel])
        small = cost[sel] - trial_cost <= 1e-15 * cost[sel]
        tiny = np.max(np.abs(step), axis=1) <= 1e-15 * (1 + np.max(np.abs(vs), axis=1))
        took = sel[better]
        v[took], r[took], g[took], cost[took] = trial[better], trial_r[better], trial_g[better], trial_cost[better]
        lam[sel] = np.where(better, lam[sel] * 0.3, lam[sel] * 10.0)
        active[sel[(better & small) | (~better & (tiny | (lam[sel] > 1e8)))]] = False
    return v, ok


# --- the root region ------------------------------------------------------------------------

def _buckets(sizes: list[int]) -> list[list[int]]:
    """Positions of the tracks whose root regions are bounded together: by length, shortest
    first, a bucket closing once it holds MIN_BUCKET tracks, or a few and the next length is
    half as long again (every pass of the barrier costs some fifty numpy calls whatever the
    bucket's size, and a track padded to the bucket's length costs in proportion to it)."""
    order = sorted(range(len(sizes)), key=lambda i: sizes[i])
    buckets: list[list[int]] = []
    current: list[int] = []
    for position, i in enumerate(order):
        current.append(i)
        following = sizes[order[position + 1]] if position + 1 < len(order) else None
        if following is None or (following != sizes[i] and (
                len(current) >= MIN_BUCKET or (len(current) >= 16 and following > 1.5 * sizes[current[0]]))):
            buckets.append(current)
            current = []
    return buckets


MIN_BUCKET = 96


def _root_regions(entries: list, watch: _Watch) -> list:
    """Each track's RootProof, proven as search.root_region and prove_root prove it (the same
    region, inflated by 1 + 1e-6, the same claimed box and padding), or None where not proven
    (the track is then solved alone). The 2d bounds of a track are found by the batched barrier
    method instead of 2d Clarabel solves; each is the safe bound of its own dual vector."""
    roots: list = [None] * len(entries)
    for members in _buckets([len(entry.points) for entry in entries]):
        for start in range(0, len(members), 2 * MAX_GROUP):
            chunk = members[start:start + 2 * MAX_GROUP]
            for i, root in zip(chunk, _root_regions_of([entries[i] for i in chunk])):
                roots[i] = root
            watch.tick(len(chunk))
    return roots


def _root_regions_of(entries: list) -> list:
    G = len(entries)
    sizes = [len(entry.points) for entry in entries]
    n = max(sizes)
    F = _functionals([entry.B for entry in entries])  # (G, D, D)
    gamma = np.array([entry.gamma for entry in entries]) * (1 + 1e-6)
    # Shorter tracks padded with constant cones (1, 0, 0): no coefficient, no effect on x.
    E = np.zeros((G, 1 + 3 * n, 4))
    E[:, 1::3, 3] = 1.0
    for g, entry in enumerate(entries):
        program = entry.chart.program
        E[g, 0] = program.linear[0]
        per_observation = np.concatenate([gamma[g] * program.den[:, None, :], program.num], axis=1)
        E[g, 1:1 + 3 * sizes[g]] = per_observation.reshape(-1, 4)
    A, b = -E[..., :-1], E[..., -1]
    Q = np.empty((G, 2 * D, D))
    Q[:, 0::2], Q[:, 1::2] = F, -F
    P = 2 * D
    x0 = np.repeat(np.array([entry.v0 for entry in entries]), P, axis=0)
    with np.errstate(all="ignore"):
        found = barrier.solve_batched(Q.reshape(G * P, D), np.repeat(A, P, axis=0), np.repeat(b, P, axis=0), n, x0)
        solved = (found.statuses == ConicStatus.OPTIMAL).reshape(G, P).all(axis=1)
        x, z = found.x.reshape(G, P, D), found.z.reshape(G, P, -1)
    roots: list = [None] * G
    for size in sorted(set(sizes)):  # each length proven on its own rows
        rows = 1 + 3 * size
        group = np.flatnonzero(np.array(sizes) == size)
        for g, root in zip(group, _proven_roots(Q[group], A[group, :rows], b[group, :rows], x[group],
                                                z[group, :, :rows], solved[group], F[group], gamma[group], size)):
            roots[g] = root
    return roots


def _functionals(Bs: list) -> np.ndarray:
    """relaxation.complete_functionals of every B: its rows, then an orthonormal basis of the
    complement of their span (from one batched SVD per number of rows)."""
    F = np.empty((len(Bs), D, D))
    by_k: dict[int, list[int]] = defaultdict(list)
    for g, B in enumerate(Bs):
        by_k[len(B)].append(g)
    for k, members in by_k.items():
        stack = np.array([Bs[g] for g in members])
        F[members, :k] = stack
        if k < D:
            F[members, k:] = np.linalg.svd(stack)[2][:, k:D]
    return F


def _proven_roots(Q, A, b, x, z, solved, F, gamma, n) -> list:
    """search.prove_root for every track, from the barrier's points and dual vectors."""
    cones = ConeSpec(nonneg=1, soc=(3,) * n)
    with np.errstate(all="ignore"):
        primal = np.einsum("gpd,gpd->gp", Q, x)
        dual = -np.einsum("gpr,gr->gp", z, b)
        values = np.minimum(primal, dual)
        lo, hi = values[:, 0::2], -values[:, 1::2]
        solved = solved & np.all(np.isfinite(values), axis=1) & np.all(lo <= hi, axis=1)
        pad = 0.5 * (hi - lo) + 1e-6 * (1 + np.abs(lo) + np.abs(hi))
        claim_lo, claim_hi = lo - pad, hi + pad
        transform = np.linalg.inv(F)
        proven = stacked.safe_bounds(Q, A, b, np.where(solved[:, None, None], z, 0.0), cones, claim_lo, claim_hi,
                                      transform)
        lower, upper = proven[:, 0::2], -proven[:, 1::2]
        solved &= np.all((claim_lo < lower) & (upper < claim_hi) & (lower <= upper), axis=1)
        pad = 1e-7 * (1 + np.abs(lower) + np.abs(upper))
    roots = []
    for g in range(len(Q)):
        roots.append(RootProof(float(gamma[g]), F[g], claim_lo[g], claim_hi[g], lower[g] - pad[g], upper[g] + pad[g],
                               list(z[g])) if solved[g] else None)
    return roots


# --- the root node --------------------------------------------------------------------------

def _root_nodes(closing: list, k: int, options: TriangulationOptions, watch: _Watch) -> list:
    """The one-node search of ``triangulate`` (bnb.branch_and_bound's root node, bounded as
    BoxProblem._bound bounds it) for tracks with a proven root region: (index, TrackResult) of
    those whose root closes the gap. The relaxations are assembled for all of them at once
    (stacked.leaf_relaxations: Relaxation.conic_data row for row) and each solved by Clarabel
    with BoxProblem's settings; each bound is the safe bound of its own dual vector."""
    norm = options.norm
    entries = [entry for entry, _ in closing]
    proofs = [root for _, root in closing]
    G = len(entries)
    num = np.array([entry.chart.program.num for entry in entries])
    den = np.array([entry.chart.program.den for entry in entries])
    linear = np.array([entry.chart.program.linear for entry in entries])
    F = np.array([proof.functionals for proof in proofs])
    bounds = np.array([[proof.lower, proof.upper] for proof in proofs])  # (G, 2, D)
    box = bounds[:, :, :k].copy()
    ub = np.array([entry.upper for entry in entries])
    reference = np.array([entry.chart.reference for entry in entries])
    with np.errstate(all="ignore"):
        E, cones, q, lower, upper, transform, built = stacked.leaf_relaxations(
            num, den, linear, F, k, bounds, box, ub, norm, reference)
    cols = E.shape[2] - 1
    A, b = -E[..., :cols], E[..., cols]
    solver = ReusableConicProgram(lean=True)  # BoxProblem's
    Z = np.zeros((G, 1, E.shape[1]))
    X = np.zeros((G, cols))
    solved = built.copy()
    for g in np.flatnonzero(built):
        result = solver.solve(q, A[g], b[g], cones)
        watch.tick()
        if result.status is not ConicStatus.OPTIMAL:
            solved[g] = False  # infeasible, or not clean: the track is solved alone
            continue
        Z[g, 0], X[g] = result.z, result.x
    with np.errstate(all="ignore"):
        safe = stacked.safe_bounds(np.broadcast_to(q, (G, 1, cols)), A, b, Z, cones, lower, upper, transform)[:, 0]
    with np.errstate(all="ignore"):
        relaxed = _costs(num, den, linear[:, 0], X[:, :D], norm)  # the relaxation's points' costs
    to_charts = np.linalg.inv(np.array([entry.chart.T for entry in entries]))  # triangulate's inv(chart.T)
    done = []
    for g in np.flatnonzero(solved & np.isfinite(safe) & (safe >= 0)):
        watch.tick()
        entry = entries[g]
        chart, v0, factor, upper_bound, B = entry.chart, entry.v0, entry.factor, entry.upper, entry.B
        program = chart.program
        unit = cost_unit(factor, norm)
        abs_gap = options.abs_gap * unit

        def tolerance(value: float) -> float:
            return max(abs_gap, options.rel_gap * abs(value))

        root = Box(box[g, 0].copy(), box[g, 1].copy())
        incumbent = v0
        inside = math.isfinite(relaxed[g])
        candidate = X[g, :D] if inside else _candidate(program, X[g, :D], v0)
        if candidate is not None:  # bnb's use of the relaxation's point
            value = float(relaxed[g]) if inside else program.cost(candidate)
            if value < upper_bound - tolerance(upper_bound):
                candidate, value = local_refine(program, candidate)
            if value < upper_bound:
                incumbent, upper_bound = candidate, value
        # Claimed a little below the safe bound computed here: the per-item verifier rebuilds the
        # chart and relaxation track by track (Chart.build, Relaxation.conic_data), whose last bits
        # differ from these stacked arrays', and recomputes the bound from the same dual (measured
        # on the Dinosaur: up to 5e-10 above its value, in these units where the incumbent costs
        # about 1; the bound claimed as computed was refused for 3 of 14,949 tracks).
        bound = float(safe[g]) - LEAF_MARGIN * (1.0 + abs(float(safe[g])))
        if not bound >= upper_bound - tolerance(upper_bound):
            continue  # not closed at the root: the track is solved alone
        leaf = LeafProof(root, float(ub[g]), "dual", Z[g, 0].copy(), bound)
        to_chart = to_charts[g]
        certificate = SearchCertificate(SCOPE, chart.reference, (B @ to_chart[:3]).tolist(), to_chart[3].tolist(),
                                        root.lo.tolist(), root.hi.tolist(), tolerance(upper_bound) / unit, True, 1)
        if options.certificate == "full":
            certificate.proof = encode(SearchProof(factor, proofs[g], [], root, [(root, leaf)]))
        lower_bound = min(bound, upper_bound) / unit
        # Checked below as the verifier would check it, all at once.
        done.append((g, track_result(chart, entry.cams, entry.points, incumbent, options, "optimal",
                                     lower_bound, 1, certificate, checked=False)))
    _check_results(entries, num, den, [result for _, result in done], [g for g, _ in done], reference, options)
    return [(entries[g].index, result) for g, result in done]


def _check_results(entries: list, num, den, results: list, rows: list[int], reference,
                   options: TriangulationOptions) -> None:
    """triangulation.track_result's checks (items.refused_by_verifier: depths, the cost's
    uncertainty, the program against the data with half the verifier's tolerance) for the
    certified ``results`` of rows ``rows`` of one root-node group, at once (stacked's forms)."""
    certified = [(row, result) for row, result in zip(rows, results) if result.status == "optimal"]
    if not certified:
        return
    chosen = np.array([row for row, _ in certified])
    solutions = np.array([result.point if result.at_infinity else result.point + [1.0] for _, result in certified])
    cams = np.array([entries[row].cams for row in chosen])
    points = np.array([entries[row].points for row in chosen])
    residuals = np.array([result.residuals for _, result in certified])
    costs = np.array([result.cost for _, result in certified])
    T = np.array([entries[row].chart.T for row in chosen])
    w = np.linalg.solve(T, solutions[..., None])[..., 0]
    inside = w[:, 3] > 0  # the verifier reads the solution in the chart: its reference depth is positive
    v0 = w[:, :3] / np.where(inside, w[:, 3], 1.0)[:, None]
    factors = np.array([entries[row].factor for row in chosen])
    with np.errstate(all="ignore"):
        in_front = np.all(np.einsum("gnj,gj->gn", cams[:, :, 2], solutions) > 0, axis=1)
        spread = cost_roundings(residuals, track_uncertainty(cams, solutions), options.norm)
        determined = spread <= 0.5 * np.maximum(options.abs_gap, options.rel_gap * np.abs(costs))
        agree, allowed = stacked.program_agrees(cams, points, num[chosen], den[chosen], T, factors, v0,
                                                reference[chosen], strictness=0.5)
        agree &= inside
        # The bound as the verifier proves it for the data's problem (proof.program_discount).
        discounts = cost_roundings(residuals, allowed, options.norm)
    for (row, result), discount in zip(certified, discounts):
        if np.isfinite(discount):
            result.lower_bound -= SOLVER_DISCOUNT_FACTOR * float(discount)
            result.gap = result.cost - result.lower_bound
            rounding = residual_rounding(np.asarray(result.residuals) + entries[row].points, entries[row].points)
            result.status, result.reason = recomputed_status("optimal", np.asarray(result.residuals), result.cost,
                                                             result.lower_bound, options, rounding)
            result.certified = result.status == "optimal"
        else:  # the proof's bound is not the data's: only the trivial bound 0 is (items.discounted)
            result.lower_bound = min(result.lower_bound, 0.0)
            result.gap = result.cost - result.lower_bound
            result.status, result.certified, result.reason = "not_certified", False, UNDISCOUNTABLE
    for (row, result), solution, passed in zip(certified, solutions, in_front & determined & agree):
        if result.status != "optimal":
            continue
        if not passed:  # rare: the reason in track_result's words, from its own checks
            entry = entries[row]
            result.status, result.certified = "not_certified", False
            item = TrackItem((entry.cams, entry.points), options.norm, entry.chart)
            result.reason = refused_by_verifier(item, solution, np.array(result.residuals), result.cost, options,
                                                entry.factor) \
                or PROGRAM_REFUSED.format("the program's residuals or depth signs differ from the data's")


def _candidate(program: FractionalProgram, v: np.ndarray, interior: np.ndarray) -> np.ndarray | None:
    """BoxProblem._candidate: the relaxation's point, or one slightly towards the interior."""
    if math.isfinite(program.cost(v)):
        return v
    for step in (1e-9, 1e-6, 1e-3):
        w = v + step * (interior - v)
        if math.isfinite(program.cost(w)):
            return w
    return None
