"""The bilinear kind (thesis chapter 8): frames of 2D points, each the image by an affine camera of a
combination of K basis shapes (exemplars, or a non-rigid shape basis). Each frame is an item:
its camera and coefficients to a certified global optimum, the linear baseline beside them."""

from __future__ import annotations

import dataclasses
from typing import Annotated, Any, Literal

from pydantic import BaseModel, Field

from geocert.kinds.base import ProblemKind
from geocert.kinds.documents import finite_or_none, outcome_document
from geocert.kinds.schema import CertificateDocument, Finite, ItemOutcome, JobBase, JobStats, Pixel, Strict, options_model
from geocert.formulations.bilinear import determinacy
from geocert.formulations.bilinear import problem
from geocert.formulations.bilinear.options import BilinearOptions
from geocert.verify.bilinear import FRAME_REGION_MEANING, FRAMES
from geocert.core import summary_notes
from geocert.core.determinacy import safely
from geocert.core.strict import Invalid
from geocert.core.self_check import SelfCheckFailed
from geocert.core.self_check import enabled as self_check_enabled
from geocert.verify.checks import verify_arrays

Point3 = Annotated[list[Finite], Field(min_length=3, max_length=3, description="[X, Y, Z]")]


class FrameIn(Strict):
    points: list[Pixel | None] = Field(min_length=1, description="one [u, v] per basis point, null when not seen")


class BilinearData(Strict):
    basis: list[Annotated[list[Point3], Field(min_length=1)]] = Field(
        min_length=1, description="K shapes of the same N points (exemplars or basis shapes)")
    frames: list[FrameIn] = Field(min_length=1, description="one image per item")


BilinearOptionsIn = options_model("BilinearOptionsIn", BilinearOptions)


class BilinearJob(JobBase):
    kind: Literal["bilinear"]
    data: BilinearData
    options: BilinearOptionsIn = Field(default_factory=BilinearOptionsIn)


class BaselineOut(BaseModel):
    method: Literal["linear"]
    camera: list[list[float]] = Field(description="linear regression of M_rk alpha_i, then the rank-1 SVD")
    coefficients: list[float]
    cost: float | None


class FrameOut(ItemOutcome):
    camera: list[list[float]] | None = Field(description="2x4 affine camera [M | t]")
    coefficients: list[float] | None = Field(description="alpha (K), summing to 1")
    shape: list[list[float]] | None = Field(description="the N fitted 3D points, sum_i alpha_i X^i")
    residuals: list[list[float] | None] | None = Field(description="observed minus imaged, null where not seen")
    baseline: BaselineOut | None


class BilinearResult(BaseModel):
    kind: Literal["bilinear"]
    norm: str
    coefficients: str
    frames: list[FrameOut]
    stats: JobStats
    certificate: CertificateDocument | None = Field(None, description='with options.certificate = "full"')


class ParsedFrames:
    def __init__(self, basis, frames):
        self.basis, self.frames = basis, frames


SCOPE = "every affine camera whose 2x3 part lies in the camera box (any translation), every coefficient vector allowed"


def frame_document(result, options: BilinearOptions) -> dict:
    certificate = None
    if result.certified or result.camera_box is not None:
        region = None
        if result.camera_box is not None:
            lo, hi = result.camera_box
            region = {"camera_lower": [lo[:3], lo[3:]], "camera_upper": [hi[:3], hi[3:]], "translation": "any",
                      "coefficients": options.coefficients,
                      "meaning": FRAME_REGION_MEANING}
        certificate = {"scope": SCOPE if region is not None else "every camera and coefficient vector",
                       "root_region": region, "tolerance": finite_or_none(result.tolerance),
                       "tolerance_met": result.certified, "leaves": result.leaves}
        if region is None and result.certified:  # a note says how a bound was proven: none uncertified
            certificate["note"] = summary_notes.TRIVIAL
        if result.proof is not None:
            certificate["proof"] = result.proof
    return {"camera": result.camera, "coefficients": result.coefficients, "shape": result.shape,
            "residuals": result.residuals, "baseline": result.baseline, **outcome_document(result),
            "certificate": certificate}


class BilinearKind(ProblemKind):
    name = "bilinear"
    description = ("Bilinear fitting (shape from exemplars, non-rigid structure from motion): per frame the affine "
                   "camera and the basis coefficients, certified globally optimal.")
    item_key = "frames"
    chunk_key = "frames"  # data["frames"][i] is item i: a task reads only its chunk's
    chunk_size = 1
    options_type = BilinearOptions
    request_model = BilinearJob
    result_model = BilinearResult
    solution_fields = ("camera", "coefficients")
    verification = FRAMES
    example = {"kind": "bilinear", "options": {"norm": "L2L2"}, "data": {
        "basis": [
        [[0.25, 0.794, 0.551], [-0.55, -0.4, 0.747], [-0.989, 0.642, 0.594], [-0.064, -0.394, -0.443], [-0.49, -0.11, 0.009], [0.107, 0.991, 0.585], [0.244, 0.978, -0.569], [-0.68, 0.225, -0.912], [-0.929, 0.03, -0.068], [0.834, 0.258, 0.028]],
        [[-0.006, -0.505, -0.976], [-0.615, 0.384, -0.599], [-0.261, -0.993, 0.66], [-0.691, -0.465, 0.761], [0.02, 0.694, 0.279], [0.484, -0.817, 0.082], [0.016, 0.743, -0.277], [0.196, -0.881, -0.225], [-0.354, -0.7, 0.633], [-0.241, 0.957, 0.18]],
        [[0.21, 0.276, 0.353], [-0.698, -0.119, -0.521], [-0.195, -0.807, 0.936], [-0.57, 0.344, -0.399], [0.748, 0.324, -0.737], [0.69, 0.89, 0.808], [0.139, -0.709, -0.615], [0.856, 0.105, -0.639], [0.768, 0.283, 0.139], [-0.247, -0.178, -0.521]]],
        "frames": [
        {"points": [[-111.45, 146.85], [-134.74, 133.29], [-28.58, 126.18], [-77.3, 102.34], [-115.72, 40.98], [-65.52, 71.84], [-124.12, 97.64], [-92.1, 160.31], [-59.94, 91.68], [-119.29, 51.61]]},
        {"points": [[-20.02, -9.14], [-47.24, 42.27], [-68.68, 121.9], None, [-39.32, -5.13], [-47.46, 20.34], [-18.17, -48.25], [23.77, -32.24], [-43.92, 61.55], [-42.69, -10.68]]}]}}

    def parse(self, data: Any, items: range | None = None) -> ParsedFrames:
        return ParsedFrames(*problem.read_data(data, items))

    @staticmethod
    def request_figures(data: dict) -> dict:
        """Shapes times points of the basis (every frame's programs grow with both)."""
        basis = data.get("basis") or []
        return {"basis_points": (len(basis) * max((len(shape) for shape in basis), default=0), "data/basis")}

    def count(self, parsed: ParsedFrames) -> int:
        return len(parsed.frames)

    def observations(self, parsed: ParsedFrames) -> int:
        return sum(int((~(f != f)[:, 0]).sum()) for f in parsed.frames if f is not None)

    def solve_item(self, parsed: ParsedFrames, index: int, options: BilinearOptions, callback) -> dict:
        from geocert.solvers.bilinear.search import fit_frame  # the conic solver, only to solve

        points = parsed.frames[index]
        checking = self_check_enabled()
        run = dataclasses.replace(options, certificate="full") if checking else options
        result = fit_frame(parsed.basis, points, run, callback)
        document = frame_document(result, run)
        if checking and result.certified:
            claim = {"index": 0, "status": document["status"], "certified": True, "cost": document["cost"],
                     "lower_bound": document["lower_bound"], "gap": document["gap"], "camera": document["camera"],
                     "coefficients": document["coefficients"], "proof": result.proof}
            try:
                verify_arrays(self.name, (parsed.basis, points), dataclasses.asdict(run), claim)
            except Invalid as exc:
                raise SelfCheckFailed(f"bilinear frame {index}: check {exc.check} failed: {exc.detail}") from exc
        if options.certificate != "full" and document["certificate"] is not None:
            document["certificate"].pop("proof", None)
        document["determinacy"] = safely(determinacy.frame, parsed.basis, points, document["camera"],
                                         document["coefficients"], document["cost"], document["lower_bound"])
        return document

    def cancelled_item(self, options: Any) -> dict:
        return {"camera": None, "coefficients": None, "shape": None, "residuals": None, "baseline": None,
                "cost": None, "lower_bound": None, "gap": None, "status": "cancelled", "certified": False,
                "nodes": 0, "elapsed_s": 0.0, "reason": "the job was cancelled before this frame started",
                "certificate": None}

    def assemble(self, options: BilinearOptions, items: list[dict], stats: dict) -> dict:
        return {"kind": self.name, "norm": options.norm, "coefficients": options.coefficients, "frames": items,
                "stats": stats}


KIND = BilinearKind()
