"""The fractional kinds' verification adapters (numpy only): how the verifier reads a
triangulation's tracks and a resection's or homography's maps from the problem data, refused unless
the service serves them; each item's proof checked against its program (the item itself, its
program rebuilt with the solver's charts: formulations/fractional/items.py); its solution from a claim;
residuals from the raw data; and the scope."""

from __future__ import annotations

import numpy as np

from geocert.core import exact
from geocert.core.certificates import OBJECTIVE_TOLERANCE
from geocert.core.determinacy import ESTIMATES_FORM, certified_gap
from geocert.core.geometry import cost_rounding, is_number, norm_cost, normalised_cameras
from geocert.core.strict import Invalid, charge, number as _number, numbers, record
from geocert.formulations.fractional.charts import Chart, MapChart
from geocert.formulations.fractional.convexity import outside_range, track_bound, verify_sublevel
from geocert.formulations.fractional.convexity_path import cost_increase
from geocert.formulations.fractional.determinacy import map_level, pooled_dof, proven_map, proven_track
from geocert.formulations.fractional.items import MapItem, TrackItem
from geocert.formulations.fractional.proof import verify_search
from geocert.formulations.fractional.resection_bound import TYPE as SUBLEVEL_BOUND, verify_resection_bound
from geocert.formulations.fractional.resection_leaves import l1_cost_increase, verify_resection_leaves
from geocert.formulations.fractional.resection_sublevel import verify_resection_sublevel
from geocert.formulations.fractional.stacked import CHECKS, proven_tracks
from geocert.verify.pooled_floor import pooled_bounds, squared_residuals

MAX_VIEWS = 1000  # views in a track, for the parser too: a chart's choice of reference takes views^2 work
MAX_POINTS = 1_000_000
LEVEL_ROUNDING = 1e-9  # the solver's two sums of one track's squared residuals differ in their last bits


def verify_convexity(item, options: dict, proof: dict, lower_claimed: float, solution, passed: list[str]) -> float:
    """The lower bound a convexity proof establishes (fractional.convexity.track_bound): an
    L2L2 track with no max_residual, a finite solution, and a radius at which the cost is proven
    convex on a ball holding every point of the scope that costs as little."""
    record(proof, "proof", ("type", "radius"), ("sublevel",))
    radius = _number(proof.get("radius"), "proof/radius")
    if options["norm"] != "L2L2" or options["max_residual"] is not None:
        raise Invalid("convexity", "a convexity proof is for L2L2 with no max_residual")
    if not (radius > 0 and np.isfinite(radius)):
        raise Invalid("convexity", "proof/radius must be a positive number")
    if not (solution[3] == 1.0 and np.all(np.isfinite(solution))):
        raise Invalid("convexity", "a convexity proof is for a finite solution [x, y, z]")
    outside = outside_range(item.cameras, item.points, solution[:3], radius)
    if outside is not None:
        raise Invalid("convexity", outside)
    bound = track_bound(item.cameras, item.points, solution[:3], radius)
    if not np.isfinite(bound):
        raise Invalid("convexity", f"nothing proven at radius {radius!r}: the ball about the solution is not shown "
                                   "to hold every point costing as little, or the cost to be convex on it")
    passed.append("convexity")
    if "sublevel" in proof:
        verify_sublevel(item.cameras, item.points, proof["sublevel"], solution, options["norm"])
        passed.append("proven_interval")
    return bound


def verify_track_search(item, options: dict, proof: dict, lower_claimed: float, solution, passed: list[str]) -> float:
    """A track's search (proof.verify_search), and its proven interval when it states one."""
    bound = verify_search(item, options, {key: value for key, value in proof.items() if key != "sublevel"},
                          lower_claimed, solution, passed)
    if "sublevel" in proof:
        verify_sublevel(item.cameras, item.points, proof["sublevel"], solution, options["norm"])
        passed.append("proven_interval")
    return bound


def verify_map_search(item, options: dict, proof: dict, lower_claimed: float, solution, passed: list[str]) -> float:
    """A map's search (proof.verify_search), and a resection's proven interval of its camera
    centre when it states one (fractional.resection_sublevel; no other map states one)."""
    bound = verify_search(item, options, {key: value for key, value in proof.items() if key != "sublevel"},
                          lower_claimed, solution, passed)
    if "sublevel" in proof:
        if (item.source.shape[1], item.target.shape[1]) != (3, 2):
            raise Invalid("format", "proof/sublevel: only a resection's proof states a proven interval")
        if options["norm"] == "L2L2":
            verify_resection_sublevel(item.source, item.target, proof["sublevel"], solution, options["norm"])
            passed.append("proven_interval")
        else:  # the L1 norms': read off the leaves of a search at the level
            # on a program of its own (the search's check has rescaled the item's)
            verify_resection_leaves(MapItem((item.source, item.target), options["norm"]), options, proof["sublevel"],
                                    solution, passed)
    return bound


def verify_map_sublevel_bound(item, options: dict, proof: dict, lower_claimed: float, solution,
                              passed: list[str]) -> float:
    """A resection's bound with no search (fractional.resection_bound), recomputed at the claim's
    camera from the stated radius and rounds; and its proven interval when it states one."""
    bound = verify_resection_bound(item.source, item.target, proof, solution, options)
    passed.append(SUBLEVEL_BOUND)
    if "sublevel" in proof:
        verify_resection_sublevel(item.source, item.target, proof["sublevel"], solution, options["norm"])
        passed.append("proven_interval")
    return bound


def _check_proven(where: str, determinacy, claim: dict, norm, proven) -> None:
    """An item's determinacy may say proven only with the intervals its claim's proof proves:
    ``proven`` (determinacy.proven_track or proven_map) of the proof's sublevel, every member (its
    level's words too), and under L2L2 at no lower a level than the estimate beside it is read
    at, which a lower level's smaller set would misstate."""
    if not isinstance(determinacy, dict) or (determinacy.get("proven") is False
                                             and determinacy.get("proven_intervals") is None):
        return
    proof = claim.get("proof") if claim.get("certified") is True else None
    sublevel = proof.get("sublevel") if isinstance(proof, dict) else None
    stated = determinacy.get("proven_intervals")
    if sublevel is None or determinacy.get("proven") is not True or not isinstance(stated, dict):
        raise Invalid("returned", f"{where}/determinacy says proven, and its certificate proves no interval")
    if not isinstance(sublevel, dict) or stated != proven(sublevel):
        raise Invalid("returned", f"{where}/determinacy/proven_intervals are not the ones its certificate proves")
    level = determinacy.get("cost_increase")
    if norm == "L2L2" and not (is_number(level) and stated["cost_increase"] >= level * (1 - LEVEL_ROUNDING)):
        raise Invalid("returned", f"{where}/determinacy/proven_intervals are proven at cost increase "
                                  f"{stated['cost_increase']!r:.12} below the {level!r:.12} its estimate is read at")


class _Pools:
    """What the pooled levels of one triangulation result are checked with, each computed once a
    document: the cameras normalised, every track's squared residuals at its returned point and
    degrees of freedom (``costs``, ``dofs``: NaN and 0 for a track pooling nothing, at infinity or
    with no point), and each pool's floor by its runs. A pool stated anew (each track may state its
    own) costs only the gathering of its tracks' figures and pooled_floor over them, charged to the
    verification's budget (strict.charge, a unit a track): recomputed per pool, the cameras and
    residuals made the check tracks x (cameras + tracks), unpaid (review 47: 51 s of CPU for 1,000
    tracks beside 40,000 unused cameras)."""

    def __init__(self, result: dict, certificate: dict):
        self.tracks, self.data = result["tracks"], certificate["data"]
        self.costs: np.ndarray | None = None
        self.dofs: np.ndarray | None = None
        self.pooled: dict = {}
        self.paid: set = set()  # the quantiles the document has paid for (pooled_floor.charge_quantiles)

    def _residuals(self) -> None:
        data = self.data
        cameras = normalised_cameras(data["cameras"])  # as the writer reads them (huge entries overflow raw)
        costs, dofs = np.full(len(self.tracks), np.nan), np.zeros(len(self.tracks))
        for j, track in enumerate(self.tracks):
            if not isinstance(track, dict) or track.get("point") is None or track.get("at_infinity") is not False:
                continue
            observed = data["tracks"][j]
            costs[j] = squared_residuals(cameras, observed["views"], observed["points"], track["point"])
            dofs[j] = 2 * len(observed["views"]) - 3
        self.costs, self.dofs = costs, dofs

    def bounds(self, runs: list) -> tuple[float, int, int] | None:
        """pooled_bounds over the tracks of ``runs`` (checked by _runs): the floor, and the least
        and most degrees of freedom the pool's tracks may give."""
        key = tuple(map(tuple, runs))
        if key not in self.pooled:
            charge(sum(b - a for a, b in runs), "the tracks of a pooled level")
            if self.costs is None:
                self._residuals()
            costs = np.concatenate([self.costs[a:b] for a, b in runs])
            dofs = np.concatenate([self.dofs[a:b] for a, b in runs])
            self.pooled[key] = pooled_bounds(costs, dofs, self.paid)  # it pools only the tracks of finite cost
        return self.pooled[key]


def _check_pooled(index: int, determinacy, result: dict, pools: _Pools) -> None:
    """A track's determinacy read at a level pooled over the job's tracks (its ``level`` as
    determinacy.pooled_level writes it) names the tracks pooled (``pooled_tracks``: runs [first,
    stop) of their indices, its own among them), and its cost_increase is at least the floor
    pooled_floor recomputes from their residuals at the points returned: a pooled level is not
    the document's word. (The pool is: a level pooled over other tracks than the job's batch is
    checked as that pool's. A level not pooled is the track's own, checked with its interval.)"""
    if not isinstance(determinacy, dict):
        return
    where = f"tracks/{index}/determinacy"
    stated_dof, runs = pooled_dof(determinacy.get("level")), determinacy.get("pooled_tracks")
    if stated_dof is None and runs is None:
        return
    tracks = result["tracks"]
    if stated_dof is None or not _runs(runs, len(tracks)) or not any(a <= index < b for a, b in runs):
        raise Invalid("returned", f"{where} is read at a level pooled over the job's tracks only with that level's "
                                  "words and the tracks pooled (pooled_tracks: runs [first, stop) of their indices, "
                                  "its own among them)")
    bounds, level = pools.bounds(runs), determinacy.get("cost_increase")
    # The degrees of freedom the level states are its pool's (the writer's pooled_increase sums
    # those of the tracks it pools, at least one): a figure its pool cannot give (none, or beyond
    # its tracks', read as a variance known better than it is) is refused. A pool giving none (no
    # track of finite residuals, or most of them 0 as the verifier computes them) bounds nothing:
    # the writer's residuals, computed otherwise, may differ from these by a rounding there.
    if bounds is None:
        return
    least, most = max(bounds[1], 1), bounds[2]
    if not least <= stated_dof <= most:
        raise Invalid("returned", f"{where}/level states {stated_dof} degrees of freedom, and the residuals of its "
                                  f"pooled_tracks give from {least} to {most} (pooled_bounds)")
    floor = bounds[0]
    if not (is_number(level) and level >= floor * (1 - LEVEL_ROUNDING)):
        raise Invalid("returned", f"{where}/cost_increase is {level!r:.12}, below {floor!r:.12}, the least the "
                                  f"residual variance pooled over its pooled_tracks gives (pooled_floor)")


def refuse_unknown_members(data, members: tuple[str, ...], key: str, item_members: tuple[str, ...]) -> None:
    """Refuse (check ``data``, naming it) a member of the data, or of one of its items (the list
    ``key``), that the kind's data do not have: ``members`` and ``item_members``, the kind's
    request model's (kinds.schema.Strict refuses any other in a job, so no genuine document holds
    one). A member no solver takes and no check reads would be hashed with the data and read as
    part of the problem (a track's "weights": a weighted cost) that the claims are not about; the
    bilinear and autocalibration kinds refuse theirs in the same words."""
    if not isinstance(data, dict):
        raise Invalid("data", "data must be an object")
    for name in data:
        if name not in members:
            raise Invalid("data", f"data/{name}: unknown field (known: {', '.join(members)})")
    entries = data.get(key)
    if not isinstance(entries, list):
        return  # _check_item_count refuses it, naming the list
    known = frozenset(item_members)
    for index, entry in enumerate(entries):
        if isinstance(entry, dict) and not entry.keys() <= known:
            name = next(name for name in entry if name not in item_members)
            raise Invalid("data", f"data/{key}/{index}/{name}: unknown field (known: {', '.join(item_members)})")


def _runs(runs, tracks: int) -> bool:
    """Whether ``runs`` are increasing, disjoint runs [first, stop) of indices of ``tracks``."""
    if not isinstance(runs, list) or not runs:
        return False
    stop = 0
    for run in runs:
        if not (isinstance(run, list) and len(run) == 2 and all(type(v) is int for v in run)
                and stop <= run[0] < run[1] <= tracks):
            return False
        stop = run[1]
    return True


def _check_map_level(where: str, determinacy, claim: dict, data: dict, index: int, norm: str = "L2L2") -> None:
    """A map's proven interval (a resection's; _check_proven has tied it to its proof) is proven
    at no lower a level than the map's own, and its determinacy's cost_increase is that level: the
    one the solver proves it at (determinacy.map_level: 3^2 times the squared residuals of the
    claim's matrix, computed exactly, over 2k - 11, at least its gap), recomputed from the data, as
    a track's is (TrackItems.check_returned). A level the document chooses shrinks the set to one
    that need not hold the camera."""
    stated = determinacy.get("proven_intervals") if isinstance(determinacy, dict) else None
    if stated is None:
        return
    points = len(data["maps"][index]["source"])
    if norm != "L2L2":  # read off a search's leaves (resection_leaves), at the L1 level; the estimate beside
        # them is of the squared residuals, read at its own level
        own = l1_cost_increase(norm, claim["cost"], points, certified_gap(claim["cost"], claim["lower_bound"]))
        if not stated["cost_increase"] >= own * (1 - LEVEL_ROUNDING):
            raise Invalid("returned", f"{where}/determinacy/proven_intervals are proven at cost increase "
                                      f"{stated['cost_increase']!r:.12} below the map's own {own!r:.12} "
                                      "(resection_leaves.l1_cost_increase)")
        return
    source, target = (np.asarray(data["maps"][index][name], dtype=float) for name in ("source", "target"))
    own = map_level(source, target, claim["matrix"], claim["cost"], claim["lower_bound"])
    if not stated["cost_increase"] >= own * (1 - LEVEL_ROUNDING):
        raise Invalid("returned", f"{where}/determinacy/proven_intervals are proven at cost increase "
                                  f"{stated['cost_increase']!r:.12} below the map's own {own!r:.12} (3^2 times its "
                                  "squared residuals over 2k - 11, at least its gap)")
    level = determinacy.get("cost_increase")
    if not (is_number(level) and abs(level - own) <= LEVEL_ROUNDING * own):
        raise Invalid("returned", f"{where}/determinacy/cost_increase is {level!r:.40}, the map's own level is "
                                  f"{own!r:.12} (3^2 times its squared residuals over 2k - 11, at least its gap)")


def _check_scope_words(where: str, summary, claim: dict, options: dict, words: str) -> None:
    """A certified item's summary ``scope`` (when stated) is the scope its proof covers, in the
    solver's words: the kind's (``words``), and under max_residual, for a search (the only proof
    whose program is limited to it; the trivial bound and a resection's sublevel bound hold over
    the whole scope), "with every residual <= max_residual" (as search.search writes it). Words
    dropping the limit claim an optimum over points no proof searched (a point with a larger
    residual may cost less); other words claim what no check reads."""
    if not isinstance(summary, dict) or "scope" not in summary:
        return
    proof = claim.get("proof")
    limit = options.get("max_residual")
    if claim.get("certified") is not True:
        # an uncertified search's summary (one that met its tolerance, or stopped) states its scope
        # as a certified search's does; without a search (no root box) the words claim nothing
        if not isinstance(summary.get("root_region"), dict):
            return
        searched = True
    else:
        searched = isinstance(proof, dict) and proof.get("type") == "branch_and_bound"
    expected = f"{words} with every residual <= {limit}" if limit is not None and searched else words
    if summary["scope"] != expected:
        raise Invalid("returned", f"{where}/certificate/scope is {summary['scope']!r:.120}, the scope its proof covers "
                                  f"is {expected!r}")


def _agrees(given, expected) -> bool:
    """A stated number or array is the one recomputed (to a relative 1e-9: the solver computed it
    with the same operations, perhaps on another machine's BLAS), of its shape, with no boolean."""
    expected = np.asarray(expected, dtype=float)
    try:
        value = numbers(given, "value", expected.shape)
    except Invalid:
        return False
    # an expected entry that overflowed matches nothing (|x - inf| <= 1e-9 * inf held for any x)
    return bool(np.all(np.isfinite(expected))
                and np.all(np.abs(value - expected) <= 1e-9 * np.maximum(1.0, np.abs(expected))))


def _stated_figure(item, solution: np.ndarray, norm: str) -> tuple[float, float]:
    """An uncertified track's or map's cost as its writer states it (items.stated_residuals) and
    the allowance it is held to: where a float evaluation's rounding could move the cost, the
    residuals computed exactly (core.exact) and 4 ulps of them, as a certified claim's (an
    allowance of the float evaluation's spread let a far map's cost be stated 0, review 38);
    elsewhere this evaluation and its rounding."""
    with np.errstate(all="ignore"):
        residuals, _, rounding = item.raw_residuals(solution)
        cost = norm_cost(residuals, norm)
        if exact.needs_exact(residuals, item.residual_uncertainty(solution), cost, norm, OBJECTIVE_TOLERANCE):
            stated = item.exact_residuals(solution)
            cost = exact.cost(stated, norm)
            return cost, OBJECTIVE_TOLERANCE * abs(cost) + exact.slack(stated, norm)
        return cost, figure_allowance(cost) + cost_rounding(residuals, rounding, norm)


def figure_allowance(cost: float) -> float:
    """How far a stated cost may be from the one the verifier recomputes for an uncertified item
    (the solver's and the verifier's rounding of the same residuals)."""
    return 1e-9 * max(1.0, abs(cost))


# A search's root region in words (the kinds write them; the verifier refuses other words). The
# earlier words (results written before they were corrected) claimed the box for every point
# (map) of the scope; a root box holds only those that could cost less than the search's cost cap.
# Stored documents hold them, so they still verify, and the report's scope says what they mean.
TRACK_REGION_MEANING = (
    "lower <= (F X) / (d . X) <= upper for every point X of the scope costing less than the search's cost cap "
    "(for a certified item: lower_bound, to within 1e-9 of it and the program's rounding), the points a search "
    "must exclude; not for every point of the scope. "
    "F = functionals (one per direction the other views' depths vary along), "
    "d = denominator (positive in front of the reference view)")
TRACK_REGION_MEANING_EARLIER = (
    "lower <= (F X) / (d . X) <= upper for every point X of the scope, "
    "F = functionals (one per direction the other views' depths vary along), "
    "d = denominator (positive in front of the reference view)")
MAP_REGION_MEANING = (
    "lower <= (F l) / (d . l) <= upper for the last row l of every map of the scope costing less than the "
    "search's cost cap (for a certified map: lower_bound, to within 1e-9 of it and the program's rounding), the "
    "maps a search must exclude; not for every map of the scope. "
    "F = functionals, d = denominator (the reference point, homogeneous)")
MAP_REGION_MEANING_EARLIER = (
    "lower <= (F l) / (d . l) <= upper for the last row l of every map in the scope, "
    "F = functionals, d = denominator (the reference point, homogeneous)")
EARLIER_MEANING_SCOPE = ("the root_region of {items} states the earlier words (its box \"for every\" point or map of "
                         "the scope); what its proof proves, and this report checks, is that the box holds every one "
                         "costing less than the search's cost cap, not every one of the scope")


def _region_words(where: str, region: dict, current: str, earlier: str, seen: list[str]) -> None:
    """A root region's meaning is the solver's words: today's, or the earlier ones a stored
    document may hold (``where`` then noted in ``seen``, for the report's scope); no other."""
    meaning = region.get("meaning")
    if meaning == earlier:
        seen.append(where)
    elif meaning != current:
        raise Invalid("returned", f"{where}/certificate/root_region/meaning is not the solver's words for a root "
                                  "region (the box holds what could cost less than the search's cost cap)")


def earlier_words_scope(seen: list[str]) -> dict:
    """The report's scope entry for root regions stated in the earlier words (none: {})."""
    if not seen:
        return {}
    items = ", ".join(seen[:5]) + (f" and {len(seen) - 5} more" if len(seen) > 5 else "")
    return {"root_region": EARLIER_MEANING_SCOPE.format(items=items)}


def _uncertified_summary(where: str, summary: dict) -> None:
    """An uncertified item's summary figures are typed as a certified one's are: ``leaves`` a count,
    ``tolerance`` a number at least 0 or null."""
    leaves, tolerance = summary.get("leaves"), summary.get("tolerance")
    if "leaves" in summary and not (type(leaves) is int and leaves >= 0):
        raise Invalid("returned", f"{where}/certificate/leaves is {leaves!r:.20}: a count")
    if tolerance is not None and not (is_number(tolerance) and tolerance >= 0):
        raise Invalid("returned", f"{where}/certificate/tolerance is {tolerance!r:.20}: a number at least 0, or null")


def _uncertified_region(where: str, region, current: str, earlier: str, seen: list[str],
                        reference: tuple[str, int, np.ndarray]) -> None:
    """An uncertified item's summary root_region (a search that stopped, or met its tolerance and
    was not certified: no proof to rebuild it from) states no more than a search can: the
    solver's words; a box with lower <= upper, finite, one entry a row of its functionals (finite,
    none all zero); the reference its chart takes (``reference``: the member's name, the chart's
    reference, and the denominator it gives, or None where the chart gives it otherwise); or none."""
    if region is None:
        return
    if not isinstance(region, dict):
        raise Invalid("returned", f"{where}/certificate/root_region must be an object or null")
    _region_words(where, region, current, earlier, seen)
    at = f"{where}/certificate/root_region"
    lower, upper, functionals = region.get("lower"), region.get("upper"), region.get("functionals")
    try:
        low = numbers(lower, f"{at}/lower", (len(lower),), "returned")
        high = numbers(upper, f"{at}/upper", (len(lower),), "returned")
        rows = numbers(functionals, f"{at}/functionals", (len(lower), len(functionals[0])), "returned")
        denominator = numbers(region.get("denominator"), f"{at}/denominator", (rows.shape[1],), "returned")
    except (Invalid, TypeError, IndexError, KeyError):
        raise Invalid("returned", f"{at}: lower, upper (one entry a row of the functionals), functionals and "
                                  "denominator must be finite numbers of matching shapes") from None
    if not np.all(low <= high):
        raise Invalid("returned", f"{at}: lower above upper (an empty box)")
    if not (np.all(np.any(rows != 0, axis=1)) and np.any(denominator != 0)):
        raise Invalid("returned", f"{at}: a functional or the denominator is all zero")
    name, index, expected = reference
    if type(region.get(name)) is not int or region[name] != index:
        raise Invalid("returned", f"{at}/{name} is {region.get(name)!r:.20}, its chart's "
                                  f"{name.replace('_', ' ')} is {index}")
    if expected is not None and not _agrees(region["denominator"], expected):
        raise Invalid("returned", f"{at}/denominator is not the one its chart's {name} gives")


def _check_root_region(where: str, summary, claim: dict, words: tuple[str, str], seen: list[str],
                       reference_name: str, chart_terms, terms: str) -> None:
    """The root_region check a track's and a map's summaries share (TrackItems, MapItems): none
    stated, or an uncertified item's (_uncertified_region), or none where the proof searched no
    box, or exactly the proof's root box in the caller's terms. ``words``: the solver's meaning
    of a root region, today's and earlier; ``chart_terms()``: the chart rebuilt from the item's
    data, as (its reference, the denominator it gives, the map from the proof's root functionals,
    trimmed to the search box, to the caller's); ``terms``: what the caller's terms are, in the
    refusal's words."""
    if not isinstance(summary, dict) or "root_region" not in summary:
        return
    region, proof = summary["root_region"], claim.get("proof")
    if claim.get("certified") is not True:
        _uncertified_summary(where, summary)
        if region is not None:
            reference, denominator, _ = chart_terms()
            _uncertified_region(where, region, *words, seen, (reference_name, reference, denominator))
        return
    if not (isinstance(proof, dict) and proof.get("type") == "branch_and_bound"):
        if region is not None:
            raise Invalid("returned", f"{where}/certificate/root_region is stated, and its proof searched no box")
        return
    if isinstance(region, dict):
        _region_words(where, region, *words, seen)
    reference, denominator, to_caller = chart_terms()
    lower, upper = proof["search_box"]
    branched = np.asarray(proof["root"]["functionals"], dtype=float)[:len(lower)]
    expected = {"lower": lower, "upper": upper, "functionals": to_caller(branched), "denominator": denominator}
    if not isinstance(region, dict) or type(region.get(reference_name)) is not int or (
            region[reference_name] != reference) or not all(
            name in region and _agrees(region[name], value) for name, value in expected.items()):
        raise Invalid("returned", f"{where}/certificate/root_region is not its proof's root box in the caller's "
                                  f"terms ({terms})")


class TrackItems:
    """The triangulation kind's verification adapter."""

    proofs = {"branch_and_bound": verify_track_search, "convexity": verify_convexity}
    hash_marks = ESTIMATES_FORM  # its tracks' determinacy estimates state their tolerances (Verification.hash_marks)
    data_items = "tracks"  # the certificate has one item per entry (verify._check_item_count)
    domain = ("every point in front of every camera (positive depth in every view, last homogeneous "
              "coordinate >= 0)")

    def __init__(self):
        # The cameras of the document being verified (the list object itself, kept alive so that
        # its identity cannot be reused, and its array): every track of a document shares them, so
        # they are read once, not once per track. The verifier forgets them at the start and end
        # of each document (forget()), so a list changed between two verifications is read anew.
        self._cameras: tuple[object, np.ndarray] | None = None
        self.earlier_words: list[str] = []  # root regions stated in the earlier words (returned_scope)

    def forget(self) -> None:
        self._cameras = None
        self.earlier_words = []

    def returned_scope(self) -> dict:
        """What the report's scope adds once the result is checked (root regions in earlier words)."""
        return earlier_words_scope(self.earlier_words)

    def check_returned(self, result: dict, certificate: dict, earlier_estimates: bool = True) -> None:
        """A track's determinacy may say proven only with the intervals its claim's proof proves:
        determinacy.proven_track of the proof's sublevel, every member (its level's words too).
        Triangulation results only: a kind that reads its points as tracks (reconstruction)
        returns no such determinacy. (An uncertified item's figures: verify.uncertified_claim.)"""
        if certificate.get("kind") != "triangulation":
            return
        norm = (certificate.get("options") or {}).get("norm")
        pools = _Pools(result, certificate)
        for index, (item, claim) in enumerate(zip(result["tracks"], certificate["items"])):
            self._check_root_region(f"tracks/{index}", item.get("certificate"), claim, certificate, index)
            _check_scope_words(f"tracks/{index}", item.get("certificate"), claim, certificate["options"],
                               "every point in front of every camera")
            determinacy = item.get("determinacy")
            _check_pooled(index, determinacy, result, pools)
            _check_proven(f"tracks/{index}", determinacy, claim, norm, proven_track)
            stated = determinacy.get("proven_intervals") if isinstance(determinacy, dict) else None
            if stated is None:
                continue
            # Proven at no lower a level than the track's own (convexity_path.cost_increase of its
            # claim: SIGMAS^2 times its residual variance, at least its gap, in its norm's units),
            # at which the solver proves every interval: a level the proof may choose shrinks the
            # set to a ball that need not hold the point observed (under any norm).
            views = len(certificate["data"]["tracks"][index]["views"])
            own = float(cost_increase(claim["cost"], claim["lower_bound"], views))
            if not stated["cost_increase"] >= own * (1 - LEVEL_ROUNDING):
                raise Invalid("returned", f"tracks/{index}/determinacy/proven_intervals are proven at cost increase "
                                          f"{stated['cost_increase']!r:.12} below the track's own {own!r:.12} (3^2 "
                                          "times its residual variance, at least its gap)")

    def _check_root_region(self, where: str, summary, claim: dict, certificate: dict, index: int) -> None:
        """A certified track's summary root_region states a fact ("lower <= (F X) / (d . X) <=
        upper for every point X of the scope costing less than the search's cost cap"): it must
        be the proof's root box in the caller's terms, as the solver writes it (fractional.
        triangulation: the search box, its branched functionals through the chart rebuilt from
        the data, the chart's depth row, its reference view), as a map's is (MapItems); none
        where the proof searched nothing (a convexity proof)."""
        def chart_terms():
            cameras, points = self.read(certificate["data"], index)
            chart = Chart.build(cameras, points, certificate["options"]["norm"])
            to_chart = np.linalg.inv(chart.T)
            return chart.reference, to_chart[3], lambda branched: branched @ to_chart[:3]

        _check_root_region(where, summary, claim, (TRACK_REGION_MEANING, TRACK_REGION_MEANING_EARLIER),
                           self.earlier_words, "reference_view", chart_terms,
                           "the search box, its functionals, denominator and reference view")

    def check_data(self, data) -> None:
        """The triangulation's data hold cameras and tracks, each track its views and points
        (kinds.triangulation's request model, the same in every format version): nothing else."""
        refuse_unknown_members(data, ("cameras", "tracks"), "tracks", ("views", "points"))

    def solution_cost(self, data: dict, claim: dict, options: dict) -> tuple[float, float] | None:
        """What an uncertified track's point costs on its observations (and the allowance for its
        rounding); None when it returns no point."""
        point = claim.get("point")
        if point is None:
            return None
        cameras, observed = self.read(data, claim["index"])
        at_infinity = claim.get("at_infinity") is True
        X = numbers(point, "point", (4,) if at_infinity else (3,), "claim")
        X = X if at_infinity else np.append(X, 1.0)
        cost, allowance = _stated_figure(TrackItem((cameras, observed), options["norm"], chart=False), X,
                                         options["norm"])
        if not np.isfinite(cost):
            raise Invalid("objective", "the point returned has no finite cost on its observations")
        return cost, allowance

    def _read_cameras(self, value) -> np.ndarray:
        remembered = self._cameras
        if remembered is not None and remembered[0] is value:
            return remembered[1]
        cameras = numbers(value, "data/cameras", (None, 3, 4), "data")
        cameras.setflags(write=False)
        self._cameras = (value, cameras)
        return cameras

    def read(self, data: dict, index: int) -> tuple:
        if not isinstance(data, dict):
            raise Invalid("data", "data must be an object")
        cameras = self._read_cameras(data.get("cameras"))
        tracks = data.get("tracks")
        if not isinstance(tracks, list) or not 0 <= index < len(tracks) or not isinstance(tracks[index], dict):
            raise Invalid("data", f"data/tracks/{index}: no such track")
        track = tracks[index]
        views = track.get("views")
        if (not isinstance(views, list) or not 2 <= len(views) <= MAX_VIEWS
                or not all(type(v) is int and 0 <= v < len(cameras) for v in views) or len(set(views)) != len(views)):
            raise Invalid("data", f"data/tracks/{index}/views: 2 to {MAX_VIEWS} distinct camera indices")
        points = numbers(track.get("points"), f"data/tracks/{index}/points", (len(views), 2), "data")
        return normalised_cameras(cameras[views]), points

    def item(self, arrays: tuple, norm: str) -> TrackItem:
        return TrackItem(arrays, norm)

    def proves_infeasible(self, data: dict, claim: dict, options: dict) -> bool:
        """Whether the data prove the track has no point in front of every camera, as the solver
        tests it (Chart.constant_depth_behind: a view's depth row exactly parallel to the
        reference's with a non-positive ratio), for a claim returning no point."""
        if claim.get("point") is not None or claim.get("cost") is not None:
            return False
        cameras, points = self.read(data, claim["index"])
        return Chart.build(cameras, points, options["norm"]).constant_depth_behind

    def proven_together(self, data: dict, options: dict, claims: list) -> tuple[set[int], tuple[str, ...]]:
        """The claims proven many at once (stacked.py, which checks their proven intervals too),
        and the checks each passed. A claim stating no interval is left to the per-item check
        when others state one, so that every claim proven here passed the same checks."""
        proven = proven_tracks(data, options, claims, MAX_VIEWS)
        stating = {i for i in proven if "sublevel" in claims[i]["proof"]}
        return (stating, CHECKS + ("proven_interval",)) if stating else (proven, CHECKS)


class MapItems:
    """A map kind's verification adapter (the (source, target) dimensions it serves)."""

    proofs = {"branch_and_bound": verify_map_search, SUBLEVEL_BOUND: verify_map_sublevel_bound}
    hash_marks = ESTIMATES_FORM  # its maps' determinacy estimates state their tolerances (Verification.hash_marks)
    data_items = "maps"
    domain = "every map that puts every point at positive depth"

    def __init__(self, kind: str, dimensions: set[tuple[int, int]]):
        self.kind, self.dimensions = kind, dimensions
        self.earlier_words: list[str] = []  # root regions stated in the earlier words (returned_scope)

    def forget(self) -> None:
        self.earlier_words = []

    def returned_scope(self) -> dict:
        """What the report's scope adds once the result is checked (root regions in earlier words)."""
        return earlier_words_scope(self.earlier_words)

    def read(self, data: dict, index: int) -> tuple:
        if not isinstance(data, dict):
            raise Invalid("data", "data must be an object")
        maps = data.get("maps")
        if not isinstance(maps, list) or not 0 <= index < len(maps) or not isinstance(maps[index], dict):
            raise Invalid("data", f"data/maps/{index}: no such map")
        entry = maps[index]
        source = numbers(entry.get("source"), f"data/maps/{index}/source", (None, None), "data")
        target = numbers(entry.get("target"), f"data/maps/{index}/target", (len(source), None), "data")
        dims = (source.shape[1], target.shape[1])
        if dims not in self.dimensions or not 1 <= len(source) <= MAX_POINTS:
            raise Invalid("data", f"data/maps/{index}: {dims[0]}D -> {dims[1]}D is not served for {self.kind}")
        return source, target

    def check_data(self, data) -> None:
        """A map kind's data hold maps, each its source and target points (kinds.resection_homography's
        request model, the same in every format version): nothing else."""
        refuse_unknown_members(data, ("maps",), "maps", ("source", "target"))

    def item(self, arrays: tuple, norm: str) -> MapItem:
        return MapItem(arrays, norm)

    def solution_cost(self, data: dict, claim: dict, options: dict) -> tuple[float, float] | None:
        """What an uncertified map's matrix costs on its points; None when it returns none."""
        if claim.get("matrix") is None:
            return None
        source, target = self.read(data, claim["index"])
        item = MapItem((source, target), options["norm"], chart=False)
        cost, allowance = _stated_figure(item, item.solution(claim), options["norm"])
        if not np.isfinite(cost):
            raise Invalid("objective", "the matrix returned has no finite cost on its points")
        return cost, allowance

    def _check_root_region(self, where: str, summary, claim: dict, certificate: dict, index: int) -> None:
        """A certified map's summary root_region states a fact ("lower <= (F l) / (d . l) <= upper
        for the last row l of every map of the scope costing less than the search's cost cap"; a
        result written before said "of every map in the scope", which no search proves): it must be the proof's root box in the
        caller's terms, as the solver writes it (fractional.maps._fit_map: the search box, its
        functionals through the chart rebuilt from the data, the reference point homogeneous), as a
        bilinear frame's is; none where the proof searched nothing."""
        def chart_terms():
            source, target = self.read(certificate["data"], index)
            chart = MapChart.build(source, target, certificate["options"]["norm"])
            to_caller = chart.last_row_basis.T @ np.linalg.inv(chart.source_norm).T
            return (chart.reference, np.append(source[chart.reference], 1.0),
                    lambda branched: branched[:, :source.shape[1]] @ to_caller)

        _check_root_region(where, summary, claim, (MAP_REGION_MEANING, MAP_REGION_MEANING_EARLIER),
                           self.earlier_words, "reference_point", chart_terms,
                           "the search box, its functionals and reference point")

    def check_returned(self, result: dict, certificate: dict, earlier_estimates: bool = True) -> None:
        """Each returned map's ``residuals`` are what its matrix leaves on the certificate's data
        (target minus the map's image), certified or not, and an uncertified map's cost is their
        norm (verify.uncertified_claim, on its claim): a residual or a cost no matrix gives is refused."""
        norm = certificate["options"].get("norm")
        for index, (entry, claim) in enumerate(zip(result.get("maps") or [], certificate["items"])):
            if isinstance(entry, dict) and isinstance(claim, dict):
                # Only a resection's proof proves an interval (verify_map_search): a homography's
                # determinacy saying proven finds no sublevel and is refused here.
                _check_proven(f"maps/{index}", entry.get("determinacy"), claim, norm, proven_map)
                _check_map_level(f"maps/{index}", entry.get("determinacy"), claim, certificate["data"], index, norm)
                self._check_root_region(f"maps/{index}", entry.get("certificate"), claim, certificate, index)
                _check_scope_words(f"maps/{index}", entry.get("certificate"), claim, certificate["options"],
                                   "every map that puts every point at positive depth")
        for index, entry in enumerate(result.get("maps") or []):
            if isinstance(entry, dict) and entry.get("matrix") is None and entry.get("residuals") not in (None, []):
                raise Invalid("returned", f"maps/{index}/residuals are given, but no matrix they derive from")
            if not isinstance(entry, dict) or entry.get("matrix") is None:
                continue
            where = f"maps/{index}"
            source, target = self.read(certificate["data"], index)
            matrix = numbers(entry["matrix"], f"{where}/matrix", (target.shape[1] + 1, source.shape[1] + 1),
                             "returned")
            item = MapItem((source, target), norm, chart=False)
            if "residuals" in entry:
                given = numbers(entry["residuals"], f"{where}/residuals", target.shape, "returned")
                # each residual as the matrix leaves it exactly, to 4 ulps (its writer states them
                # so): where a float evaluation's rounding could move the cost (far off, a residual
                # is a difference of terms 1e8 in size that each machine's kernels round otherwise),
                # any window of that rounding let residuals of 1e-8 px be stated 0 (reviews 37 and
                # 38). Elsewhere a document written before states float residuals, each within
                # twice what the data determine it to (and its rounding) of the exact one.
                with np.errstate(all="ignore"):
                    exact_residuals = item.exact_residuals(matrix)
                    allowed = 4 * np.spacing(np.abs(exact_residuals))
                    floats, _, rounding = item.raw_residuals(matrix)
                    determined = item.residual_uncertainty(matrix)
                    if not exact.needs_exact(floats, determined, norm_cost(floats, norm), norm, OBJECTIVE_TOLERANCE):
                        allowed = allowed + 2 * np.minimum(rounding, determined)
                if not np.all(np.abs(given - exact_residuals) <= allowed):
                    raise Invalid("returned", f"{where}/residuals are not what its matrix leaves on the data")


TRACKS = TrackItems()
