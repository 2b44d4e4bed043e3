"""Claims the verifier refuses, on hostile random map problems: how many certified resection
(3D -> 2D) and homography (2D -> 2D) results the per-item verifier does not accept.

Each problem is a random camera or plane homography seen through hostile data: source coordinates
scaled by 1e-6 .. 1e6 and offset far from the origin (up to 1e6 times their spread), targets scaled
by 1e-6 .. 1e6 and offset too, a minimal + 1 count of points or up to 24, and some of: points nearly
coplanar (resection) or collinear (homography), a point nearly on the map's principal plane (depth
1e-3 .. 1e-9 of the others'), a point behind it, gross outliers, a near-duplicate point, a point at
the source's centroid; noise 0.01 .. 30 target units (before scaling), targets clipped to 1e8.
Data the service refuses (fractional.inputs.check_correspondences) are skipped and counted.

Every certified result (full certificate, time_limit_s 2, max_nodes 300) goes to the per-item
verifier exactly as the service's certificate carries it (claim_of with the matrix, through
JSON). A certified result the verifier refuses breaks the promise that a certified answer is
checkable; this prints the count and the verifier's reasons.

    .venv/bin/python -m bench.hostile_maps [--seeds 1,2,3] [--norms L2L2,L2L1,L1L1] [--problems 24]
    .venv/bin/python -m bench.hostile_maps --show 2:5   # seed 2, problem 5: its ingredients and data
    .venv/bin/python -m bench.hostile_maps --verbose    # also each row's statuses and reasons
    .venv/bin/python -m bench.hostile_maps --forge      # genuine certificates perturbed (below)

--forge takes genuine certificates of maps whose searches branch (and one with per-term caps) and
perturbs the claim (cost, lower_bound, matrix: negated, scaled by 1e+-300, a slightly costlier one)
and every part of the proof (scale, gamma, root bounds and duals, tightening rounds, search box,
leaves, leaf proofs' bounds, duals, kinds and cost caps, caps rounds), alone and with a false lower
bound; it prints what the verifier accepts and whether that is false (a lower bound above the cost
of a map known to exist, or a cost that is not its matrix's).

Targets scaled by 1e6 and offset by 1e6 of that lie beyond the clip: such problems have every
target at the same corner and are degenerate or trivially fitted (kept: hostile too).

Nothing here asserts; tests/solvers/fractional/test_hostile_maps.py holds the checked cases.
"""

from __future__ import annotations

import argparse
import collections
import copy
import dataclasses
import json
import time

import numpy as np

from geocert.verify import checks as verify
from geocert.core.certificates import BOUND_TOLERANCE, pack, unpack
from geocert.core.geometry import InputError
from geocert.solvers.fractional.inputs import check_correspondences
from geocert.solvers.fractional.maps import fit_map
from geocert.formulations.fractional.results import claim_of
from testing.hostile_maps import random_camera, options_for, problem, refused

KINDS = ("resection", "homography")
INGREDIENTS = ("flat", "principal", "behind", "outliers", "duplicate", "centroid")


# --- forging: a genuine certificate, perturbed --------------------------------------------------

def _scaled(text: str, factor: float) -> str:
    return pack(unpack(text) * factor)


def _shrunk(box: list, fraction: float) -> list:
    lo, hi = np.array(box[0]), np.array(box[1])
    middle, half = (lo + hi) / 2, (hi - lo) / 2 * (1 - fraction)
    return [(middle - half).tolist(), (middle + half).tolist()]


def _proof_forgeries(proof: dict) -> dict:
    """Changes of a proof's numbers (each a function of a deep copy of the proof)."""
    if proof.get("type") != "branch_and_bound":
        return {}
    best = max(range(len(proof["proofs"])), key=lambda i: proof["proofs"][i].get("bound") or 0.0)

    def each(path):  # a change applied to every proof record
        def change(p):
            for record in p["proofs"]:
                path(record)
        return change

    forgeries = {
        "scale x 1.001": lambda p: p.update(scale=p["scale"] * 1.001),
        "scale x 2": lambda p: p.update(scale=p["scale"] * 2),
        "scale x 0.5": lambda p: p.update(scale=p["scale"] * 0.5),
        "gamma x 0.5": lambda p: p["root"].update(gamma=p["root"]["gamma"] * 0.5),
        "root bounds shrunk 10%": lambda p: p["root"].update(bounds=_shrunk(p["root"]["bounds"], 0.1)),
        "root claim shrunk 10%": lambda p: p["root"].update(claim=_shrunk(p["root"]["claim"], 0.1)),
        "root duals x 2": lambda p: p["root"].update(duals=[_scaled(z, 2.0) for z in p["root"]["duals"]]),
        "root duals zero": lambda p: p["root"].update(duals=[_scaled(z, 0.0) for z in p["root"]["duals"]]),
        "functionals x 2": lambda p: p["root"].update(functionals=(np.array(p["root"]["functionals"]) * 2).tolist()),
        "no tightening": lambda p: p.update(tightening=[]),
        "search box shrunk 1%": lambda p: p.update(search_box=_shrunk(p["search_box"], 0.01)),
        "last leaf dropped": lambda p: p.update(leaves=p["leaves"][:-1]),
        "a leaf shrunk 1%": lambda p: p["leaves"].__setitem__(0, _shrunk(p["leaves"][0][:2], 0.01)
                                                              + p["leaves"][0][2:]),
        "every leaf to the best proof": lambda p: [leaf.__setitem__(2, best) for leaf in p["leaves"]],
        "a leaf's proof null": lambda p: p["leaves"][0].__setitem__(2, None),
        "bounds x (1 + 1e-6)": each(lambda r: r.update(bound=r["bound"] * (1 + 1e-6)) if r.get("bound") else None),
        "bounds x 1.01": each(lambda r: r.update(bound=r["bound"] * 1.01) if r.get("bound") else None),
        "duals z x 2": each(lambda r: r.update(z=_scaled(r["z"], 2.0), bound=(r.get("bound") or 0) * 2)),
        "duals z x 1.001, bound too": each(lambda r: r.update(z=_scaled(r["z"], 1.001),
                                                                 bound=(r.get("bound") or 0) * 1.001)),
        "kind farkas": each(lambda r: r.update(kind="farkas")),
        "kind depth": each(lambda r: r.update(kind="depth")),
        "upper_bound x 0.5": each(lambda r: r.update(upper_bound=r["upper_bound"] * 0.5)
                                  if r.get("upper_bound") else None),
        "upper_bound null": each(lambda r: r.update(upper_bound=None)),
        "tightening upper_bound x 0.5": lambda p: [t.update(upper_bound=t["upper_bound"] * 0.5)
                                                   for t in p["tightening"]],
        "tightening box_out shrunk 10%": lambda p: [t.update(box_out=_shrunk(t["box_out"], 0.1))
                                                    for t in p["tightening"]],
    }
    if proof.get("caps"):
        forgeries.update({
            "caps upper_bound x 0.5": lambda p: [c.update(upper_bound=c["upper_bound"] * 0.5) for c in p["caps"]],
            "caps duals x 2": lambda p: [c.update(duals=[_scaled(z, 2.0) if z else z for z in c["duals"]])
                                         for c in p["caps"]],
            "caps box shrunk 10%": lambda p: [c.update(box=_shrunk(c["box"], 0.1)) for c in p["caps"]],
            "caps observations rotated": lambda p: [c.update(observations=c["observations"][1:] + c["observations"][:1])
                                                    for c in p["caps"]],
            "caps dropped": lambda p: p.update(caps=[]),
        })
    return forgeries


def _true_cost(source, target, matrix, norm: str) -> float:
    """The cost of ``matrix`` in extended precision (what a claim's cost must be)."""
    S = np.hstack([source, np.ones((len(source), 1))]).astype(np.longdouble)
    proj = S @ np.asarray(matrix, dtype=np.longdouble).T
    r = np.asarray(target, dtype=np.longdouble) - proj[:, :-1] / proj[:, -1:]
    if norm == "L2L2":
        return float(np.sum(r * r))
    if norm == "L2L1":
        return float(np.sum(np.sqrt(np.sum(r * r, axis=1))))
    return float(np.sum(np.abs(r)))


def forge(cases) -> None:
    """Each case: (name, kind, source, target, norm). The genuine certificate, then its forgeries:
    whether the verifier accepts each and, when it does, whether what it accepted is false (a
    lower bound above the cost of a map known to exist, or a cost that is not its matrix's)."""
    print("| case | forgery | verdict | false? |")
    print("|---|---|---|---|")
    for name, kind, source, target, norm in cases:
        options = options_for(norm)
        result = fit_map(source, target, options)
        if not result.certified:
            print(f"| {name} | (genuine) | {result.status}: {result.reason} | |")
            continue
        tight = fit_map(source, target, dataclasses.replace(options, rel_gap=1e-9, abs_gap=1e-12, max_nodes=5000,
                                                            time_limit_s=30.0))
        best = min(result.cost, tight.cost)  # a map of this cost exists: no true lower bound exceeds it
        genuine = json.loads(json.dumps(claim_of(result, matrix=result.matrix)))
        M = np.array(result.matrix)
        # A map a little costlier than the one returned (by 1e-7 to 1e-5 relative): claiming its
        # cost as the lower bound is false, since the returned map costs less.
        step = np.random.default_rng(0).normal(size=M.shape) * np.abs(M).max()
        for size in 10.0 ** np.arange(-12, -2, 0.5):
            worse = M + step * size
            worse_cost = _true_cost(source, target, worse, norm)
            if worse_cost > result.cost * (1 + 1e-7):
                break

        def claim_with(base, **fields):
            claim = copy.deepcopy(base)
            claim.update(fields)
            claim["gap"] = claim["cost"] - claim["lower_bound"]
            return claim

        claims = {
            "(genuine)": genuine,
            "cost x (1 - 1e-6)": claim_with(genuine, cost=result.cost * (1 - 1e-6)),
            "lower_bound = cost": claim_with(genuine, lower_bound=result.cost),
            "lower_bound x (1 + 1e-6)": claim_with(genuine, lower_bound=min(result.cost,
                                                                            result.lower_bound * (1 + 1e-6))),
            "matrix negated": claim_with(genuine, matrix=(-M).tolist()),
            "matrix x 1e-300": claim_with(genuine, matrix=(M * 1e-300).tolist()),
            "matrix x 1e300": claim_with(genuine, matrix=(M * 1e300).tolist()),
            "matrix x 1e-310 (subnormal)": claim_with(genuine, matrix=(M * 1e-310).tolist()),
            "a worse matrix, its cost": claim_with(genuine, matrix=worse.tolist(), cost=worse_cost),
            "a worse matrix, lower_bound = its cost": claim_with(genuine, matrix=worse.tolist(), cost=worse_cost,
                                                                 lower_bound=worse_cost),
        }
        for label, change in _proof_forgeries(genuine["proof"]).items():
            false_base = claims["a worse matrix, lower_bound = its cost"]
            for base_label, base in (("", genuine), (" + worse matrix, lower = its cost", false_base)):
                claim = copy.deepcopy(base)
                try:
                    change(claim["proof"])
                except (TypeError, KeyError, IndexError):
                    continue
                claims[label + base_label] = claim
        refusals = collections.Counter()
        for label, claim in claims.items():
            try:
                _, bound = verify.verify_arrays(kind, (source, target), dataclasses.asdict(options), claim)
            except verify.Invalid as exc:
                refusals[exc.check] += 1
                if label == "(genuine)":
                    print(f"| {name} | {label} | refused: {exc.check}: {exc.detail[:80]} | |")
                continue
            false = []
            if claim["lower_bound"] * (1 - BOUND_TOLERANCE) > best * (1 + 1e-12):
                false.append(f"lower_bound {claim['lower_bound']!r} > {best!r}, the cost of a map")
            true_cost = _true_cost(source, target, claim["matrix"], norm)
            if abs(true_cost - claim["cost"]) > 1e-8 * abs(true_cost):  # beyond OBJECTIVE_TOLERANCE's 1e-9
                false.append(f"cost {claim['cost']!r}, its matrix costs {true_cost!r}"
                             + (" (by less than abs_gap)" if abs(true_cost - claim["cost"]) <= options.abs_gap else ""))
            print(f"| {name} | {label} | accepted (bound {bound:.10g}, lower {claim['lower_bound']:.10g}) | "
                  f"{'**FALSE**: ' + '; '.join(false) if false else 'no'} |", flush=True)
        leaves = len(genuine["proof"].get("leaves", [])) if genuine["proof"] else 0
        print(f"| {name} | {len(claims)} forgeries in all ({leaves} leaves, {result.nodes} nodes, "
              f"caps {len(genuine['proof'].get('caps', []))}) | refused: {dict(refusals)} | |", flush=True)


def forge_cases() -> list:
    """Maps whose searches branch (so that leaves, tightening and coverage are exercised): a
    resection of 12 points with 10 px noise, homographies of 10 and 5 points with 10 and 20 px
    noise; a resection of 60 points with four 30 px outliers (per-term caps); and hostile problems
    of the bench that were certified."""
    cases = []
    for kind, n, count, noise, norm, outliers in (("resection", 3, 7, 20.0, "L1L1", 0),
                                                  ("resection", 3, 9, 10.0, "L2L2", 0),
                                                  ("homography", 2, 10, 10.0, "L2L2", 0),
                                                  ("homography", 2, 5, 20.0, "L2L2", 0),
                                                  ("homography", 2, 5, 20.0, "L1L1", 0),
                                                  ("resection", 3, 60, 1.0, "L2L2", 4)):
        rng = np.random.default_rng([8, 0] if outliers else [7, count, n])
        P = random_camera(rng)
        M = P if n == 3 else P[:, [0, 1, 3]]
        X = rng.normal(size=(count, n))
        proj = np.hstack([X, np.ones((count, 1))]) @ M.T
        x = proj[:, :2] / proj[:, 2:] + rng.normal(size=(count, 2)) * noise
        x[:outliers] += rng.normal(size=(outliers, 2)) * 30.0
        cases.append((f"{kind} {count} pts {noise:g} px{' + outliers' if outliers else ''} {norm}", kind, X, x, norm))
    for seed, index, norm in ((2, 8, "L2L2"), (1, 12, "L2L1")):
        p = problem(seed, index)
        cases.append((f"hostile {seed}:{index} {norm}", p["kind"], p["source"], p["target"], norm))
    return cases


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", default="1,2,3")
    parser.add_argument("--norms", default="L2L2,L2L1,L1L1")
    parser.add_argument("--problems", type=int, default=24)
    parser.add_argument("--show", default=None, help="seed:index: print that problem and stop")
    parser.add_argument("--verbose", action="store_true", help="name each refused problem")
    parser.add_argument("--forge", action="store_true", help="perturb genuine certificates instead")
    args = parser.parse_args()
    if args.forge:
        forge(forge_cases())
        return
    if args.show:
        seed, index = (int(s) for s in args.show.split(":"))
        p = problem(seed, index)
        print(json.dumps({k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in p.items()}))
        return
    print("| seed | kind | norm | certified | refused by the verifier | reasons |")
    print("|---|---|---|---|---|---|")
    start, cpu = time.perf_counter(), time.process_time()
    skipped = collections.Counter()
    named = []
    for seed in (int(s) for s in args.seeds.split(",")):
        problems = []
        for index in range(args.problems):
            p = problem(seed, index)
            try:
                check_correspondences(p["source"], p["target"], "data/maps/0")
            except InputError as exc:
                skipped[exc.reason.split(":")[0][:50]] += 1
                continue
            problems.append((index, p))
        for kind in KINDS:
            for norm in args.norms.split(","):
                options = options_for(norm)
                reasons, certified, total, statuses = collections.Counter(), 0, 0, collections.Counter()
                for index, p in problems:
                    if p["kind"] != kind:
                        continue
                    total += 1
                    try:
                        result = fit_map(p["source"], p["target"], options)
                    except Exception as exc:  # a crash is a finding too
                        reasons[f"solver raised {type(exc).__name__}"] += 1
                        named.append((seed, index, norm, p["ingredients"], f"raised {exc!r}"))
                        continue
                    statuses[result.status if result.certified or not result.reason
                             else f"{result.status}: {result.reason[:60]}"] += 1
                    if result.certified:
                        certified += 1
                        if why := refused(kind, p["source"], p["target"], result, options):
                            reasons[why[:70]] += 1
                            named.append((seed, index, norm, p["ingredients"], why))
                print(f"| {seed} | {kind} | {norm} | {certified}/{total} | {sum(reasons.values())} | "
                      f"{'; '.join(f'{k} ({v})' for k, v in reasons.items()) or '-'} |", flush=True)
                if args.verbose:
                    print(f"<!-- statuses {dict(statuses)} -->", flush=True)
    print(f"\nskipped (the service refuses the data): {dict(skipped) or 0}; "
          f"wall {time.perf_counter() - start:.0f} s, CPU {time.process_time() - cpu:.0f} s")
    for seed, index, norm, ingredients, why in named:
        print(f"- seed {seed} problem {index} {norm} {ingredients}: {why[:300]}")


if __name__ == "__main__":
    main()
