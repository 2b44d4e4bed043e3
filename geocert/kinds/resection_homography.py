"""The map kinds: resection (3D -> 2D) and homographies (2D -> 2D, 3D -> 3D), independent maps
from correspondences, one item each."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, Field

from geocert.kinds.base import ProblemKind
from geocert.kinds.documents import brief_certificate, certificate_summary, outcome_document
from geocert.kinds.schema import CertificateDocument, Finite, ItemOutcome, JobBase, JobStats, Strict, options_model
from geocert.core.geometry import COORDINATE_LIMIT, InputError, number_array
from geocert.solvers.fractional.inputs import check_correspondences
from geocert.verify.fractional import MAP_REGION_MEANING
from geocert.verify.adapters import VERIFIED_KINDS
from geocert.formulations.fractional.options import MapOptions
from geocert.formulations.fractional.results import MapResult

Coordinates = Annotated[list[Finite], Field(min_length=2, max_length=3)]


class MapIn(Strict):
    source: list[Coordinates] = Field(min_length=1, description="source points (3D for resection)")
    target: list[Coordinates] = Field(min_length=1, description="target points, same order (pixels for resection)")


class MapsData(Strict):
    maps: list[MapIn] = Field(min_length=1, description="independent maps, solved in parallel")


MapOptionsIn = options_model("MapOptionsIn", MapOptions)


class ResectionJob(JobBase):
    kind: Literal["resection"]
    data: MapsData
    options: MapOptionsIn = Field(default_factory=MapOptionsIn)


class HomographyJob(JobBase):
    kind: Literal["homography"]
    data: MapsData
    options: MapOptionsIn = Field(default_factory=MapOptionsIn)


class MapOut(ItemOutcome):
    matrix: list[list[float]] | None = Field(description="Frobenius norm 1, reference depth positive")
    residuals: list[list[float]] = Field(description="target minus the map's image, per point")


class MapsResult(BaseModel):
    kind: Literal["resection", "homography"]
    norm: str
    maps: list[MapOut]
    stats: JobStats
    certificate: CertificateDocument | None = Field(None, description='with options.certificate = "full"')


@dataclass
class ParsedMaps:
    maps: list[tuple[np.ndarray, np.ndarray] | None]


def map_document(result: MapResult, detail: str = "full", full_certificate: bool = False) -> dict:
    reference = getattr(result.certificate, "reference", None)  # a search's (a bound with no search has no region)
    region = {"reference_point": reference} if reference is not None else {}
    certificate = brief_certificate(result, full_certificate) if detail == "brief" else certificate_summary(
        result, region, MAP_REGION_MEANING, "every map that puts every point at positive depth")
    return {"matrix": result.matrix, "residuals": result.residuals, **outcome_document(result),
            "certificate": certificate}


class MapKind(ProblemKind):
    """Independent maps P^n -> P^m of the given (n, m) dimensions, one item each."""

    item_key = "maps"
    chunk_key = "maps"  # data["maps"][i] is item i: a task reads only its chunk's
    streamed_result = True  # the result: its items, the norm and stats (batch.streams_result)
    chunk_size = 1
    options_type = MapOptions
    result_model = MapsResult
    solution_fields = ("matrix",)

    def __init__(self, name: str, dimensions: set[tuple[int, int]], description: str, request_model: type,
                 example: dict):
        self.name, self.dimensions, self.description = name, dimensions, description
        self.request_model, self.example = request_model, example
        self.verification = VERIFIED_KINDS[name].verification

    def parse(self, data: Any, items: range | None = None) -> ParsedMaps:
        if not isinstance(data, dict) or "maps" not in data:
            raise InputError("data/maps", "is required: a list of {source, target} correspondences")
        if not isinstance(data["maps"], list) or not data["maps"]:
            raise InputError("data/maps", "must be a non-empty list")
        maps: list = [None] * len(data["maps"])
        for i in items if items is not None else range(len(data["maps"])):
            where = f"data/maps/{i}"
            entry = data["maps"][i]
            if not isinstance(entry, dict) or "source" not in entry or "target" not in entry:
                raise InputError(where, "must be an object with 'source' and 'target'")
            arrays = []
            for key in ("source", "target"):
                array = number_array(entry[key], f"{where}/{key}", "a list of points (lists of numbers)", 2,
                                     COORDINATE_LIMIT)
                if array.shape[0] == 0:
                    raise InputError(f"{where}/{key}", "must be a non-empty list of points of one dimension")
                arrays.append(array)
            source, target = arrays
            if (source.shape[1], target.shape[1]) not in self.dimensions:
                allowed = " or ".join(f"{n}D -> {m}D" for n, m in sorted(self.dimensions))
                raise InputError(where, f"{source.shape[1]}D -> {target.shape[1]}D points; {self.name} takes {allowed}")
            check_correspondences(source, target, where)
            maps[i] = (source, target)
        return ParsedMaps(maps)

    @staticmethod
    def request_figures(data: dict) -> dict:
        """The most points in one map: its every conic program has a row per point, and a map's
        first programs do not stop at its time limit."""
        largest, field = 0, "data/maps"
        for i, entry in enumerate(data.get("maps") or ()):
            points = len(entry.get("source") or ()) if isinstance(entry, dict) else 0
            if points > largest:
                largest, field = points, f"data/maps/{i}/source"
        return {"map_points": (largest, field)}

    def count(self, parsed: ParsedMaps) -> int:
        return len(parsed.maps)

    def observations(self, parsed: ParsedMaps) -> int:
        return sum(len(pair[0]) for pair in parsed.maps if pair is not None)  # parsed items only

    def solve_item(self, parsed: ParsedMaps, index: int, options: MapOptions, callback) -> dict:
        from geocert.solvers.fractional.maps import fit_map  # the conic solver, only to solve

        from geocert.core.determinacy import safely
        from geocert.formulations.fractional import determinacy

        source, target = parsed.maps[index]
        result = fit_map(source, target, options, callback)
        document = map_document(result, options.detail, options.certificate == "full")
        if options.detail == "full":
            document["determinacy"] = safely(determinacy.map_, source, target, result.matrix, result.cost,
                                             determinacy.stated_lower_bound(result))
        proof = (document.get("certificate") or {}).get("proof")  # a full certificate's only (either detail)
        if self.name == "resection" and result.certified and options.norm == "L2L2" and (
                proof.get("type") in ("branch_and_bound", "sublevel_bound") if proof is not None else options.detail == "full"):
            # Proven at the estimate's level, whatever the detail (the proof is the same in both); a
            # trivial proof has no place for one.
            sublevel = determinacy.prove_map(source, target, result.matrix, result.cost, result.lower_bound,
                                             document.get("determinacy"))
            if sublevel is not None and proof is not None:
                proof["sublevel"] = sublevel
        elif proof is not None and isinstance(proof.get("sublevel"), dict) and document.get("determinacy"):
            # An L1 resection's, read off its search's leaves (fractional.resection_leaves)
            document["determinacy"]["proven_intervals"] = determinacy.proven_map(proof["sublevel"])
            document["determinacy"]["proven"] = True
        return document

    def cancelled_item(self, options: Any) -> dict:
        return map_document(MapResult("cancelled", False, reason="the job was cancelled before this map started"))

    def assemble(self, options: MapOptions, items: list[dict], stats: dict) -> dict:
        return {"kind": self.name, "norm": options.norm, "maps": items, "stats": stats}


RESECTION = MapKind("resection", {(3, 2)}, "Camera resectioning: the projective camera (3x4) from 3D-2D matches, "
                                           "certified globally optimal.", ResectionJob, {
    "kind": "resection", "options": {"norm": "L2L2"}, "data": {"maps": [{
        "source": [[0, 0, 5], [1, 0, 6], [0, 1, 7], [1, 1, 5], [-1, 0.5, 6], [0.5, -1, 8], [-0.5, -0.5, 5.5]],
        "target": [[320, 240], [453.8, 240.1], [320.2, 354.1], [480.1, 400], [186.5, 306.7], [370, 139.9],
                   [247.3, 167.2]]}]}})
HOMOGRAPHY = MapKind("homography", {(2, 2), (3, 3)}, "Homographies of P^2 (from 2D-2D matches) or P^3 (from "
                                                     "3D-3D matches), certified globally optimal.", HomographyJob, {
    "kind": "homography", "options": {"norm": "L2L2"}, "data": {"maps": [{
        "source": [[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.4], [0.2, 0.8]],
        "target": [[10, 10], [30.2, 11], [31, 29.6], [9.6, 30.1], [20.3, 19.2], [14.1, 26.3]]}]}})
