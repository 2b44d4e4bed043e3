"""Full certificates: what a search records so that anyone can check its bound (docs/certificate.md).

The records are plain data (numpy only): the solver fills them, :mod:`geocert.verify` reads them
back from JSON. Arrays of dual values are stored as base64 of little-endian float64 (exact and
half the size of decimal text); boxes and scalars are JSON numbers (Python writes floats so that
they read back bit for bit).
"""

from __future__ import annotations

import base64
import hashlib
import json
import math
import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from geocert.core.bnb import Box

FORMAT = "geocert-certificate"
# Every tolerance is relative, with no absolute floor a document could exploit (docs/certificate.md,
# "Trust model"). A bound the verifier recomputes may fall below the one claimed by this fraction
# of it: what rebuilding the data on another machine (other BLAS, other rounding) can change. The
# same fraction applies to cost caps and to the claimed lower bound; the objective has its own.
BOUND_TOLERANCE = 1e-9
OBJECTIVE_TOLERANCE = 1e-9
# How far a residual coordinate recomputed from the data may be from anyone else's computation of
# it: this fraction of |image| + |observed| (about 45 units in their last place). The cost's slack
# from it counts against the gap: a claim is certified only when its cost plus that slack is within
# the tolerance of its lower bound (at coordinates of 5e7, 1e-12 let a map costing 9e-4 claim 0).
ROUNDING = 1e-14
# How far a residual computed from a program and from the raw data may differ when its terms are
# far larger than itself (a point near a principal plane, data offset far from the origin): this
# fraction of the terms' size (the sum of their products' magnitudes) over the depth. Measured
# where this allowance, not the others, admits a residual: 0.44 to 1.37 times 1e-16 of it (the 7
# far-offset maps of bench.hostile_maps, 2 georeferenced resections), so 1e-14 leaves a margin of
# about 70; a program coefficient wrong by 1e-6 of itself is still refused on georeferenced data
# (tests/solvers/fractional/test_hostile_maps.py).
TERMS_ROUNDING = 1e-14


def residual_rounding(image: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """Each residual coordinate's rounding allowance (ROUNDING of the sizes of image and
    observation), as the verifier counts it and the solvers certify against it."""
    return ROUNDING * (np.abs(image) + np.abs(observed))


VERSION = 2  # 2: problem_sha256 covers the options a claim depends on; strict numbers throughout
# The options a claim depends on: the cost (norm), the scope (max_residual) and the tolerance.
CLAIM_OPTIONS = ("norm", "max_residual", "rel_gap", "abs_gap")


@dataclass
class RootProof:
    """Bounds on ``y = F v`` over the residual region {every residual <= gamma, domain rows}.

    Each bound is proven over ``claim`` (a box on y); as the region is convex and meets
    ``claim`` only strictly inside it, the region lies inside ``claim``, so the bounds hold on
    the whole region. ``duals[2 j]`` proves ``lower[j]``, ``duals[2 j + 1]`` proves ``upper[j]``.
    """

    gamma: float
    functionals: np.ndarray  # F (d x d): B's k rows, then the complement's
    claim_lower: np.ndarray
    claim_upper: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    duals: list[np.ndarray]


@dataclass
class TighteningProof:
    """One round of bound tightening: over ``box_in``, every point costing at most
    ``upper_bound`` has ``B v`` within ``box_out``; a side without a dual was left as it was."""

    upper_bound: float
    box_in: Box
    box_out: Box
    duals: list[np.ndarray | None]  # 2 per functional: lower side, upper side


@dataclass
class CapProof:
    """One round of per-term caps: over ``box``, for every point costing at most
    ``upper_bound``, the terms of the observations other than ``observations[j]`` sum to at least
    what ``duals[j]`` proves (None: nothing proven), over the relaxation built with the caps of
    the rounds before."""

    upper_bound: float
    box: Box
    observations: np.ndarray
    duals: list[np.ndarray | None]


@dataclass
class LeafProof:
    """Why no point of ``box`` costing at most ``upper_bound`` costs less than ``bound``:
    ``dual`` (a dual vector of the box's relaxation), ``farkas`` (the relaxation is infeasible:
    bound is infinite), ``depth`` (some depth is at most 0 on the whole box) or ``tightened``
    (node tightening: ``duals`` prove the range of ``B v`` over the box's points costing at most
    ``upper_bound``; the leaves using it lie outside that range, so their bound is infinite)."""

    box: Box
    upper_bound: float
    kind: str
    z: np.ndarray | None
    bound: float
    duals: list[np.ndarray | None] | None = None  # tightened: 2 per functional, as TighteningProof's
    caps: int = 0  # rounds of per-term caps (SearchProof.caps) its relaxation was built with


@dataclass
class SearchProof:
    """Everything a search proves, in the program's scaled units (cost times ``unit``)."""

    scale: float  # the residuals' factor (unit = scale^2 for L2L2, scale otherwise)
    root: RootProof
    tightening: list[TighteningProof] = field(default_factory=list)
    search_box: Box | None = None
    leaves: list[tuple[Box, LeafProof | None]] = field(default_factory=list)
    caps: list[CapProof] = field(default_factory=list)  # rounds of per-term caps, after the tightening
    quadratic: bool = False  # L2L2 terms over the envelope of |n|^2 / s^2 (Relaxation.quadratic)


def pack(array: np.ndarray | None) -> str | None:
    """Base64 of little-endian float64, subnormal entries written as 0: a verifier refuses them
    (strict.dual_vector), and every bound computed from the vector reads them as 0 too
    (cones.safe_lower_bounds), so the bound recorded is the one recomputed."""
    if array is None:
        return None
    array = np.array(array, dtype="<f8")
    array[(array != 0) & (np.abs(array) < 2.0 ** -1022)] = 0.0
    return base64.b64encode(array.tobytes()).decode("ascii")


def unpack(text: str | None) -> np.ndarray | None:
    if text is None:
        return None
    return np.frombuffer(base64.b64decode(text, validate=True), dtype="<f8").astype(float)


def _box(box: Box) -> list[list[float]]:
    return [box.lo.tolist(), box.hi.tolist()]


def encode(proof: SearchProof) -> dict:
    """The JSON form of a search's proof (the ``proof`` member of an item's certificate)."""
    proofs: list[dict] = []
    index: dict[int, int] = {}
    leaves = []
    for box, leaf in proof.leaves:
        if leaf is not None and id(leaf) not in index:
            index[id(leaf)] = len(proofs)
            # Infinite numbers as null (strict JSON): a bound, or the cost cap of a box closed
            # before any incumbent was known (no cap: the proof holds for every point of the scope).
            record = {"box": _box(leaf.box),
                      "upper_bound": leaf.upper_bound if math.isfinite(leaf.upper_bound) else None, "kind": leaf.kind,
                      "z": pack(leaf.z), "bound": leaf.bound if math.isfinite(leaf.bound) else None}
            if leaf.duals is not None:
                record["duals"] = [pack(z) for z in leaf.duals]
            if leaf.caps:
                record["caps"] = leaf.caps
            proofs.append(record)
        leaves.append(_box(box) + [index[id(leaf)] if leaf is not None else None])
    root = proof.root
    encoded = {
        "type": "branch_and_bound",
        "scale": proof.scale,
        "root": {"gamma": root.gamma, "functionals": root.functionals.tolist(),
                 "claim": [root.claim_lower.tolist(), root.claim_upper.tolist()],
                 "bounds": [root.lower.tolist(), root.upper.tolist()],
                 "duals": [pack(z) for z in root.duals]},
        "tightening": [{"upper_bound": t.upper_bound, "box_in": _box(t.box_in), "box_out": _box(t.box_out),
                        "duals": [pack(z) for z in t.duals]} for t in proof.tightening],
        "search_box": _box(proof.search_box),
        "proofs": proofs,
        "leaves": leaves,  # [lower corner, upper corner, index into proofs or null (trivial bound 0)]
    }
    if proof.quadratic:  # the relaxation the leaves' duals are for (absent: the envelope of t / s)
        encoded["relaxation"] = "quadratic"
    if proof.caps:  # only when the search capped terms (maps that branch)
        encoded["caps"] = [{"upper_bound": c.upper_bound, "box": _box(c.box),
                            "observations": [int(i) for i in c.observations], "duals": [pack(z) for z in c.duals]}
                           for c in proof.caps]
    return encoded


def canonical_json(value: Any) -> bytes:
    return json.dumps(value, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False).encode()


def hashed_numbers(value: Any) -> Any:
    """``value`` with every number written as the float it denotes (0.0 for -0.0; an integer as
    its nearest float, as every reader reads it, this verifier's too: only one beyond the floats'
    range is kept as written). JSON has one kind of number, and other writers than Python's write
    the same numbers differently (JavaScript's JSON.stringify, Go's encoding/json and jq write 640.0
    as 640 and -0.0 as 0): a hash of Python's text of them refused a genuine result re-serialised
    by one (review 45), and one of an integer no float holds, kept exact, a genuine result that a
    reader of doubles wrote again (review 47). Hashed so, a document's hashes are those of the
    numbers' values. The definition: data_digest writes the same text without this copy."""
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return value
    if isinstance(value, float):
        return 0.0 if value == 0.0 else value
    if isinstance(value, int):
        try:
            return float(value) + 0.0  # + 0.0: no negative zero
        except OverflowError:
            return value
    if isinstance(value, list):
        return [hashed_numbers(item) for item in value]
    if isinstance(value, dict):
        return {key: hashed_numbers(item) for key, item in value.items()}
    return value


# In canonical JSON text: a string (skipped whole, so that nothing inside one is read as a number),
# an integer, or a negative zero: the tokens whose value's text differs from Python's text of them.
# A float's repr always has "." or "e" and is its value's text already.
# The string's pattern unrolled (runs of plain characters, then an escape and its run): the
# alternation per character kept a backtracking mark a character, about 150 bytes of memory for
# each byte of a long string (review 48).
_VALUE_TOKENS = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"|(?<![\w.+-])-?(?:\d+|0\.0)(?![\w.])')


def _value_token(token: bytes, exact_integers: bool) -> bytes | None:
    """A token's text as its value's, or None where it is that already."""
    if token[0] == 0x22 or b"." in token and token != b"-0.0":
        return None
    if token == b"-0.0":
        return b"0.0"
    integer = int(token)
    try:
        value = float(integer) + 0.0
    except OverflowError:
        return None
    return None if exact_integers and int(value) != integer else repr(value).encode()


def data_digest(data: Any, values: bool = True, exact_integers: bool = False) -> Any:
    """A SHA-256 fed the text every hash of a document's data begins with: '{"data":', the data's
    canonical JSON text (canonical_json), its numbers as their values (canonical_json of
    hashed_numbers(data), to the byte) unless ``values`` is False, and ','; each hash goes on from a
    copy of it. Written from Python's text of the data and fed to the hash piece by piece: a
    converted copy of the data took 25 times its text in memory (review 47), this about 4 times
    (the text, as str and as bytes). ``exact_integers``: an integer no float holds exactly kept as
    written, the values' form of the documents written before review 47."""
    digest = hashlib.sha256(b'{"data":')
    text = canonical_json(data)
    if not values:
        digest.update(text)
    else:
        view, done = memoryview(text), 0
        for match in _VALUE_TOKENS.finditer(text):
            written = _value_token(match.group(), exact_integers)
            if written is not None:
                digest.update(view[done:match.start()])
                digest.update(written)
                done = match.end()
        digest.update(view[done:])
    digest.update(b",")
    return digest


def _finished(digest: Any, rest: dict) -> str:
    """The hash of canonical_json({"data": ..., **rest}) from data_digest's: "data" sorts before
    every other member these hashes have."""
    if not rest or any(key <= "data" for key in rest):
        raise ValueError(f"a hash's members sort after 'data': {sorted(rest)}")
    digest = digest.copy()
    digest.update(canonical_json(rest)[1:])
    return digest.hexdigest()


def data_hash(kind: str, data: Any, values: bool = True, digest: Any = None) -> str:
    """SHA-256 of the problem data, as canonical JSON of {"kind", "data"} (sorted keys, no spaces),
    its numbers as their values (hashed_numbers; ``values`` False: as Python wrote them, the form of
    documents written before). ``digest``: data_digest(data, values), when the caller has it (a
    reader hashing one document several ways writes its data once)."""
    return _finished(data_digest(data, values) if digest is None else digest, {"kind": kind})


def problem_hash(kind: str, data: Any, options: dict, names: tuple[str, ...] | None = None,
                 marks: dict | None = None, values: bool = True, digest: Any = None) -> str:
    """SHA-256 of everything a claim depends on: canonical JSON of {"kind", "data", "options"}
    with the options ``names`` only (a kind's own, as declared, or for None CLAIM_OPTIONS: the
    fractional kinds'),
    numbers as floats (max_residual null when unset; every number as its value, hashed_numbers,
    unless ``values`` is False: data_hash); and ``marks``, the form a kind's documents
    declare beyond their options (its Verification.hash_marks: determinacy.ESTIMATES_FORM), as
    "form" (absent from the hash of a document written before the kind declared one).
    ``digest``: as data_hash's."""
    claimed = {name: options.get(name) for name in (CLAIM_OPTIONS if names is None else names)}
    for name, value in claimed.items():
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            claimed[name] = float(value)
    hashed = {"kind": kind, "options": claimed}
    if marks:
        hashed["form"] = marks
    if values:
        hashed = hashed_numbers(hashed)
    return _finished(data_digest(data, values) if digest is None else digest, hashed)
