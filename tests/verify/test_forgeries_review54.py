"""Review 54: the stratified unit reference frame (proof/reference_scale, the earlier frame's
2^EARLIER_FRAME_EXPONENT limit), the cuts ending at the safe bound less twice its rounding margin
(cuts.reproducible_bounds), and embedded certificates swapped across items, kinds and documents.

Tried:

- proof/reference_scale (on a genuine stratified document of today's writer, whose scale is
  16384.0) set on both stages, the affine stage's only or the metric stage's only to 0, 0.0, -0.0,
  minus the scale, +-5e-324, 1.5, 2 and 0.5 times the scale, the scale's next float up, 1e308, inf,
  nan, the scale as a string, true, false, null, [scale], {"v": scale}; deleted from one stage or
  from both (the document then read in the reference as given, an earlier writer's frame); stated
  on a direct proof.
- The data re-posed in another world frame (the input is a projective reconstruction: any 4x4 H,
  cameras P H and points H^-1 X, images unchanged) and solved again by today's writer: the stored
  stratified scene (a) as given, (b) its image units scaled by 2^-10 (image_size and cameras), (c)
  upgraded by its own returned upgrade (a metric frame), each with the reference camera's centre
  moved to the origin and then the fourth coordinate scaled by 2^-20 to 2^28; the same without the
  move to the origin (an ordinary change of world units); the reconstruction's calibration
  certificate's data re-posed likewise (its tie to the result, calibration_tie, compares images,
  which no world frame changes).
- Cut leaves: whether any slab edge a writer states is used beyond the verifier's own recomputation
  (cuts.reproducible_bounds ends the writer's slabs at the safe bound less twice its margin).
- Swaps: each pair of items of every stored multi-item document (triangulation_l2l2, _l2l1,
  homography3_l2l1, resection_l1l1, bilinear_l1l1, _l2l2, reconstruction) swapped as they are, with
  their indices swapped back, with the result's entries swapped too, the result entries' own
  certificate summaries swapped alone, and data, items and indices swapped with the hashes made
  again (the result left); the reconstruction's camera_certificate and calibration_certificate
  swapped between reconstruction and reconstruction_labelled, and a stored autocalibration
  document's certificate carried as a reconstruction's calibration certificate.

Found, and fixed after the review (the frame's fix, in the solver and the verifier alike: see the
end of class 1):

1. The unit reference frame fixes the reference camera's scale, not the world's. normalise builds
   T0 from the reference P_r = [A | a] and then scales each camera [A_j | a_j] T0 to Frobenius
   norm sqrt(3). With the world frame chosen so that the reference's centre is the origin (a = 0:
   the common P_0 = [K | 0] or [I | 0] convention of projective reconstructions), scaling the
   fourth coordinate by k (cameras P diag(1, 1, 1, k), points diag(1, 1, 1, 1/k) X: the same images)
   leaves the reference camera, and so reference_scale, exactly as it was, but multiplies every
   other camera's translation by k in the frame: the Frobenius scaling then shrinks their left
   blocks, and the modulus costs, by about 1/k^2. At k = 2^20 the affine stage's costs are of the
   order of its absolute gap (1e-12, options.abs_gap): the root's lower bound 0 closes it at a
   plane whose cost, 7.9e-13, is "within abs_gap", and the metric stage then certifies, for that
   plane, a K far from the truth. This is exactly the failure the unit reference frame was merged
   to mend (the reference times 2^28, K 4,250 px off certified), reached in the unit frame by the
   world frame instead of the camera's scale; the earlier frame's 2^8 limit bounds the reference's
   scale only, and leaves it open there too. Reproduction:
   * autocalibration: the stored stratified scene (tests/data/certificates/
     autocalibration_stratified.json), cameras P @ U and points inv(U) X with U its own returned
     upgrade, then H = [[I, C], [0, 1]] @ diag(1, 1, 1, 2^24) with C the reference camera's (5)
     centre, solved with its own options (solve_job): both stages certified (the metric stage in
     one node, 0.06 s), K focal 634 and 603 at (545, 594) with skew 10 (truth 1000 at (500, 500),
     the document's within 2e-4 px of it), 397 px off, and verify_any valid; 2^26: 353 px off,
     certified in 1.9 s; 2^24: K 293 px off, the metric stage at its time limit (uncertified: no
     false claim); the image units times 2^-10 as well: the same K, scaled. Without moving the
     centre to the origin (a change of world units), the reference's own translation scales too
     and its scale absorbs it: K right. The direct method on the same data at 2^24: K within
     1e-4 px of the truth (its frame, the reference as given, did not move here).
   * reconstruction: the stored reconstruction's calibration certificate's data re-posed by
     H = [[I, C], [0, 1]] @ diag(1, 1, 1, 2^20) and solved again: K [[2233.7, -6.4, 480], [0,
     2345.3, 120]] certified (the genuine one: 796.45 at (319.5, 239.5)); carried as the
     reconstruction's calibration certificate, with certified_K, the autocalibration stage's K and
     restated stages, calibration.difference and on_range_edge, and the warnings the verifier asks
     for (certified_K_on_range_edge, returned_K_not_certified's figures), the document verifies.
     (The stored scene is a critical motion, so the result already says the tracks do not
     determine K, and the forged K lies on its ranges' edges, which the warning now required says;
     the claim that it is the optimum the certificate proves is still false.)
   * the earlier frame (a proof stating no reference_scale, read in the reference as given where
     the preconditioned reference's largest entry is below 2^8): its limit reads the reference's
     entries, which this world frame leaves as they were. The stored scene with its image units
     times 2^-10 (image_size and cameras: the preconditioned reference then in [0.5, 1)),
     upgraded, centred and its fourth coordinate times 2^34, solved by a writer posing the
     stages in the reference as given (the kind's prepare with unit_reference=False: proofs
     without reference_scale): K focal 632 and 601 px (at the 1000-px scale), both stages
     certified, frames.earlier_frame_readable true, and the document verifies. (Unscaled image
     units, 2^28: the reference as given lies 2^-10 below unit scale there, so that frame is the
     unit frame's times 2^-10, and K came out right.)
   The same re-posing at scale 1 certifies the true K and verifies (the controls at the end), so
   the xfail tests fail on the scale alone.
   Fixed: frames.normalise brings the fourth coordinate to unit size by the power of two
   (frames.world_unit_scale) that puts the other cameras' median ||a_j|| / ||A_j|| in the reference
   frame into [2^-6, 2^-5); proofs state it as world_scale and the verifier holds it to the data's.
   Proofs stating none (the earlier writers') are read in the world as given only where that ratio
   lies in [2^-20, 2^8) (frames.earlier_world_readable). The three cases are the tests below.

Held (refused, or accepted only where the edit claims nothing false):

- reference_scale: every value above refused (the verifier recomputes the scale and only
  compares; true is refused though True == 1.0, a string or a list though they may print alike),
  but for the scale written as an int (16384 for 16384.0: the same number, as JavaScript writes
  it); deleted from one stage refused (check_claims: both stages in one frame); deleted from both:
  read in the reference as given, whose costs differ (refused, objective); stated on a direct
  proof: refused.
- Cuts: the writer's cut value is not written (encode_leaves states axis and sign); the verifier
  recomputes each cut's value from its dual over its box (proofs._cut_value), moves a leaf at most
  SIDE_TOLERANCE of the root box onto it and recomputes the cut over any box so grown
  (_moved_faces), and every leaf must lie beyond its recomputed cut and the leaves cover the box;
  a cut leaf's bound is its own cap, the cap the cut's program was built with. Nothing the writer
  states of a slab's edge is used beyond that recomputation. On the stored five-view document's
  affine stage (103 cuts): a cut's slab pushed into the part it keeps by 1e-12 to 1e-3 of its
  width (coverage, then not beyond its cut), its cap times 10 or its sign flipped: refused.
- An uncertified stratified stage (no proof to state its frame) has its cost read in the unit
  frame and, where that is not the cost stated, in the reference as given (solution_cost): not
  pursued further; its plane or K is stated in input coordinates, the same object in both frames,
  and only its cost figure could be the other frame's.
- The direct method on the world frame of class 1 (2^24): K within 1e-4 px of the truth.
- Swaps: every swap above refused (index, objective, the result's cost or its certificate summary
  not its claim's, the camera certificate's map not the returned points, the certified K not the
  calibration certificate's); the consistent reordering (data, items, indices and result together)
  is the same claims in another order.
"""

from __future__ import annotations

import copy
import itertools
import json

import numpy as np
import pytest

from geocert.formulations.autocalibration import problem as autocalibration_problem
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import rehash, stored
from tests.support import refused as _refused


def _valid(document: dict) -> bool:
    return verify_any(json.loads(json.dumps(document))).valid


def _reposed(data: dict, options: dict, k: float, upgrade: np.ndarray | None = None) -> dict:
    """The data in another world frame (the same images): upgraded by ``upgrade`` when given,
    the reference camera's centre moved to the origin, the fourth coordinate scaled by ``k``."""
    data = copy.deepcopy(data)
    P, X = np.asarray(data["cameras"], dtype=float), np.asarray(data["points"], dtype=float)
    if upgrade is not None:
        P, X = P @ upgrade, X @ np.linalg.inv(upgrade).T
        P /= np.abs(P).max(axis=(1, 2))[:, None, None]
        X /= np.abs(X).max(axis=1)[:, None]
    reference = autocalibration_problem.prepare(P, X, tuple(data["image_size"]),
                                                dict(options.get("intrinsics") or {})).norm.reference
    H = np.eye(4)
    H[:3, 3] = -np.linalg.solve(P[reference, :, :3], P[reference, :, 3])
    H = H @ np.diag([1.0, 1.0, 1.0, k])
    P, X = P @ H, X @ np.linalg.inv(H).T
    P[reference, :, 3] = 0.0  # its centre, exactly
    data["cameras"], data["points"] = P.tolist(), X.tolist()
    return data


def _solve(data: dict, options: dict) -> dict:
    from geocert.jobs.runner import solve_job

    return json.loads(json.dumps(solve_job({"kind": "autocalibration", "data": data, "options": options})))


@pytest.fixture(scope="module")
def genuine() -> dict:
    """Today's writer's stratified document of the stored scene, its reference's centre at the
    origin (the world frame moved, the images the same): reference_scale 16384.0."""
    document = stored("autocalibration_stratified")
    certificate = document["certificate"]
    return _solve(_reposed(certificate["data"], certificate["options"], 1.0), certificate["options"])


# Held: reference_scale is the data's, compared, never used

BAD_SCALES = [0, 0.0, -0.0, "minus", 5e-324, -5e-324, "1.5x", "2x", "half", "next", 1e308, float("inf"),
              float("nan"), "string", True, False, None, "list", "object"]


def _scale_value(tag, scale: float):
    return {"minus": -scale, "1.5x": 1.5 * scale, "2x": 2 * scale, "half": scale / 2,
            "next": float(np.nextafter(scale, np.inf)), "string": str(scale), "list": [scale],
            "object": {"v": scale}}.get(tag, tag) if isinstance(tag, str) else tag


# (world_scale, the world's power of two (frames.world_unit_scale), is held to the data's as
# reference_scale is: both members are edited alike.)
MEMBERS = ["reference_scale", "world_scale"]


@pytest.mark.parametrize("member", MEMBERS)
@pytest.mark.parametrize("stages", [(0, 1), (0,), (1,)], ids=["both", "affine", "metric"])
@pytest.mark.parametrize("tag", BAD_SCALES, ids=[repr(t) for t in BAD_SCALES])
def test_a_scale_other_than_the_datas_is_refused(genuine, tag, stages, member):
    scale = genuine["certificate"]["items"][0]["proof"][member]
    assert type(scale) is float and np.frexp(scale)[0] == 0.5 and _valid(genuine)
    forged = copy.deepcopy(genuine)
    for stage in stages:
        forged["certificate"]["items"][stage]["proof"][member] = _scale_value(tag, scale)
    assert not verify_any(forged).valid


def test_a_world_scale_beyond_the_largest_float_is_refused_naming_it(genuine):
    """An int JSON carries beyond the largest float is named, not an OverflowError's format failure."""
    forged = copy.deepcopy(genuine)
    for item in forged["certificate"]["items"]:
        item["proof"]["world_scale"] = 10 ** 400
    report = verify_any(json.loads(json.dumps(forged)))
    assert not report.valid and "proof/world_scale is" in report.first_failure["detail"], report.first_failure


def test_the_reference_scale_written_as_an_int_is_the_same_number(genuine):
    document = copy.deepcopy(genuine)
    scale = document["certificate"]["items"][0]["proof"]["reference_scale"]
    for item in document["certificate"]["items"]:
        item["proof"]["reference_scale"] = int(scale)
    assert _valid(document)


@pytest.mark.parametrize("member", MEMBERS)
@pytest.mark.parametrize("stages", [(0,), (1,), (0, 1)], ids=["affine", "metric", "both"])
def test_a_scale_deleted_is_refused(genuine, stages, member):
    """(world_scale deleted from both: the proofs read as the writer before it, whose costs differ.)"""
    forged = copy.deepcopy(genuine)
    for stage in stages:
        del forged["certificate"]["items"][stage]["proof"][member]
    assert not _valid(forged)


def test_the_world_scale_written_as_an_int_is_the_same_number():
    """(The genuine document's world_scale is 2^-10: here the fourth coordinate times 2^-20 makes it 2^10.)"""
    certificate = stored("autocalibration_stratified")["certificate"]
    document = _solve(_reposed(certificate["data"], certificate["options"], 2.0 ** -20), certificate["options"])
    scale = document["certificate"]["items"][0]["proof"]["world_scale"]
    assert scale >= 1.0 and _valid(document)
    for item in document["certificate"]["items"]:
        item["proof"]["world_scale"] = int(scale)
    assert _valid(document)


# Held: a cut's slab is where the verifier recomputes it

@pytest.mark.parametrize("edit", ["1e-12", "1e-9", "1e-6", "1e-3", "cap", "sign"])
def test_a_cut_slab_moved_past_its_recomputed_cut_is_refused(edit):
    forged = stored("autocalibration_five_views")
    region = forged["certificate"]["items"][0]["proof"]["regions"][0]
    index = next(i for i, proof in enumerate(region["proofs"]) if proof.get("kind") == "cut")
    proof, leaf = region["proofs"][index], next(leaf for leaf in region["leaves"] if leaf[2] == index)
    axis, sign = proof["axis"], proof["sign"]
    if edit == "cap":
        proof["upper_bound"] *= 10
    elif edit == "sign":
        proof["sign"] = -sign
    else:
        width = leaf[1][axis] - leaf[0][axis]
        if sign > 0:
            leaf[1][axis] += float(edit) * width
        else:
            leaf[0][axis] -= float(edit) * width
    assert not _valid(forged)


# Held: swapped items and embedded certificates

LISTS = {"triangulation": "tracks", "homography": "maps", "resection": "maps", "bilinear": "frames",
         "reconstruction": "points"}
DATA_LISTS = {"triangulation": "tracks", "homography": "maps", "resection": "maps", "bilinear": "frames",
              "reconstruction": "tracks"}


def _swapped(document: dict, i: int, j: int, how: str) -> dict:
    forged = copy.deepcopy(document)
    items, entries = forged["certificate"]["items"], forged[LISTS[forged["kind"]]]
    if how in ("items", "items_indexed", "items_indexed_result", "data_rehashed"):
        items[i], items[j] = items[j], items[i]
        if how != "items":
            items[i]["index"], items[j]["index"] = items[j]["index"], items[i]["index"]
    if how in ("items_indexed_result", "result"):
        entries[i], entries[j] = entries[j], entries[i]
    if how == "result_summaries":
        entries[i]["certificate"], entries[j]["certificate"] = entries[j]["certificate"], entries[i]["certificate"]
    if how == "data_rehashed":
        data = forged["certificate"]["data"][DATA_LISTS[forged["kind"]]]
        data[i], data[j] = data[j], data[i]
        rehash(forged["certificate"])
    return forged


@pytest.mark.parametrize("how", ["items", "items_indexed", "items_indexed_result", "result", "result_summaries",
                                 "data_rehashed"])
@pytest.mark.parametrize("name", ["triangulation_l2l2", "triangulation_l2l1", "homography3_l2l1", "resection_l1l1",
                                  "bilinear_l1l1", "reconstruction"])
def test_items_swapped_within_a_document_are_refused(name, how):
    document = stored(name)
    for i, j in itertools.islice(itertools.combinations(range(len(document["certificate"]["items"])), 2), 2):
        assert not _valid(_swapped(document, i, j, how)), (i, j)


@pytest.mark.parametrize("key", ["camera_certificate", "calibration_certificate"])
def test_a_reconstructions_embedded_certificate_from_another_is_refused(key):
    a, b = stored("reconstruction"), stored("reconstruction_labelled")
    assert a[key] != b[key]
    for into, source in ((a, b), (b, a)):
        forged = copy.deepcopy(into)
        forged[key] = copy.deepcopy(source[key])
        assert not _valid(forged)


@pytest.mark.parametrize("name", ["autocalibration_stratified", "autocalibration_five_views", "autocalibration_direct"])
def test_an_autocalibration_documents_certificate_as_a_calibration_certificate_is_refused(name):
    forged = stored("reconstruction")
    forged["calibration_certificate"] = stored(name)["certificate"]
    assert not _valid(forged)


# The world frame's scale (class 1 of the docstring)

TRUTH = np.array([[1000.0, 0.0, 500.0], [0.0, 1000.0, 500.0], [0.0, 0.0, 1.0]])


@pytest.mark.parametrize("exponent", [-20, 8, 28])
def test_a_world_frame_with_the_reference_at_the_origin_and_any_fourth_scale_certifies_the_true_K(exponent):
    document = stored("autocalibration_stratified")
    certificate = document["certificate"]
    data = _reposed(certificate["data"], certificate["options"], 2.0 ** exponent, np.asarray(document["upgrade"]))
    result = _solve(data, certificate["options"])
    assert all(stage["certified"] for stage in result["stages"]) and _valid(result)
    assert np.abs(np.asarray(result["K"]) - TRUTH).max() < 0.01
    assert all(2.0 ** -6 <= item["proof"]["world_scale"] * _world_ratio(data) < 2.0 ** -5
               for item in result["certificate"]["items"])


def _world_ratio(data: dict) -> float:
    return autocalibration_problem.prepare(np.asarray(data["cameras"]), np.asarray(data["points"]),
                                           tuple(data["image_size"]), {}, world=False).norm.world_ratio


def _calibration_forged(k: float) -> dict:
    """The stored reconstruction carrying a calibration certificate solved again on its own
    projective data re-posed with the reference's centre at the origin and the fourth coordinate
    times k, with every figure the verifier recomputes from it restated."""
    from geocert.formulations.reconstruction import calibration_claim

    forged = stored("reconstruction")
    genuine = forged["calibration_certificate"]
    result = _solve(_reposed(genuine["data"], genuine["options"], k), genuine["options"])
    K, certificate = result["K"], result["certificate"]
    forged["calibration_certificate"] = certificate
    stage = next(s for s in forged["stages"] if s.get("name") == "autocalibration")
    stage["K"] = K
    for given, claim in zip(stage["stages"], certificate["items"]):
        for name in ("cost", "lower_bound", "gap", "status"):
            given[name] = claim[name]
    calibration = forged["summary"]["calibration"]
    calibration["certified_K"] = K
    returned = np.asarray(calibration["K"])
    Kc = np.asarray(K)
    calibration["difference"] = {
        "focal_percent": float(100.0 * (returned[0, 0] / Kc[0, 0] - 1.0)),
        "principal_point_px": float(np.hypot(returned[0, 2] - Kc[0, 2], returned[1, 2] - Kc[1, 2])),
        "aspect": float(returned[1, 1] / returned[0, 0] - Kc[1, 1] / Kc[0, 0]),
        "skew_px": float(returned[0, 1] - Kc[0, 1])}
    report = verify_any(json.loads(json.dumps(forged)))
    detail = (report.first_failure or {}).get("detail", "")
    if "summary/calibration/difference is" in detail:  # the verifier's own figures, as the pipeline rounds them
        import ast

        calibration["difference"] = ast.literal_eval(detail.split("the returned and certified K give ", 1)[1])
    report = verify_any(json.loads(json.dumps(forged)))
    detail = (report.first_failure or {}).get("detail", "")
    if "summary/calibration/on_range_edge is" in detail:
        import ast

        calibration["on_range_edge"] = ast.literal_eval(detail.split(" give ", 1)[1])
    edges = calibration["on_range_edge"]
    warnings = forged["summary"]["warnings"]
    for warning in warnings:
        if warning["code"] == "returned_K_not_certified":
            warning["detail"] = warning["detail"].replace("focal +0.05%, principal point 0.7 px",
                                                          calibration_claim.moved_figures(calibration["difference"]))
    if edges:
        warnings.insert(1, {"code": "certified_K_on_range_edge", "detail": calibration_claim.edge_warning(edges)})
    return forged


def test_a_calibration_certificate_solved_in_another_world_frame_certifies_the_genuine_K():
    forged = _calibration_forged(2.0 ** 20)
    genuine = np.asarray(stored("reconstruction")["summary"]["calibration"]["certified_K"])
    assert np.abs(np.asarray(forged["summary"]["calibration"]["certified_K"]) - genuine).max() < 0.5
    assert _valid(forged)


def _earlier_world_writer(monkeypatch, data: dict, options: dict, unit_reference: bool) -> dict:
    """``data`` solved by a writer posing the stages in the world as given (proofs stating no
    world_scale): the reference as given too (stating neither) or at unit scale (reference_scale
    only), with its self-check (the verifier's) off."""
    import types

    import geocert.kinds.autocalibration as kind

    given = types.SimpleNamespace(**vars(autocalibration_problem))
    given.prepare = lambda *args, **kwargs: autocalibration_problem.prepare(
        *args, **{**kwargs, "unit_reference": unit_reference, "world": False})
    monkeypatch.setattr(kind, "autocalibration_problem", given)
    monkeypatch.delenv("GEOCERT_SELF_VERIFY", raising=False)
    return _solve(data, options)


def test_an_earlier_frames_proof_in_a_world_frame_with_a_large_fourth_scale_is_refused(monkeypatch):
    """A proof stating neither scale, K 400 px off: the reference's 2^8 limit holds, the world's not."""
    from geocert.formulations.autocalibration import frames

    document = stored("autocalibration_stratified")
    certificate = document["certificate"]
    data = copy.deepcopy(certificate["data"])
    units = np.diag([2.0 ** -10, 2.0 ** -10, 1.0])
    data["cameras"] = np.einsum("ab,ibc->iac", units, np.asarray(data["cameras"], dtype=float)).tolist()
    data["image_size"] = [size * 2.0 ** -10 for size in data["image_size"]]
    data = _reposed(data, certificate["options"], 2.0 ** 34, np.asarray(document["upgrade"]))
    result = _earlier_world_writer(monkeypatch, data, certificate["options"], unit_reference=False)
    assert not any({"reference_scale", "world_scale"} & item["proof"].keys() for item in result["certificate"]["items"])
    problem = autocalibration_problem.prepare(np.asarray(data["cameras"]), np.asarray(data["points"]),
                                              tuple(data["image_size"]), {}, unit_reference=False)
    assert frames.earlier_frame_readable(problem.norm) and not frames.earlier_world_readable(problem.norm)
    assert "proof/world_scale is not stated" in _refused(result)["detail"]


@pytest.mark.parametrize("exponent, readable", [(8, True), (20, False)])
def test_a_unit_reference_frames_proof_is_read_in_the_world_as_given_only_near_unit_scale(monkeypatch, exponent,
                                                                                         readable):
    """The writer before world_scale (reference_scale only): the stored scene's ratio 2^-9.8 times
    2^8 is read, its K true; times 2^20 (K 0.9 px off as that writer solved it) refused."""
    document = stored("autocalibration_stratified")
    certificate = document["certificate"]
    data = _reposed(certificate["data"], certificate["options"], 2.0 ** exponent, np.asarray(document["upgrade"]))
    result = _earlier_world_writer(monkeypatch, data, certificate["options"], unit_reference=True)
    assert all("reference_scale" in item["proof"] and "world_scale" not in item["proof"]
               for item in result["certificate"]["items"])
    if readable:
        assert _valid(result) and np.abs(np.asarray(result["K"]) - TRUTH).max() < 0.01
    else:
        assert "proof/world_scale is not stated" in _refused(result)["detail"]


# The controls: the same re-posing without the large scale gives the genuine K, verified (the
# xfail tests above fail on the scale, not on the forging)

def test_the_stored_scene_reposed_at_scale_one_certifies_the_true_K():
    document = stored("autocalibration_stratified")
    certificate = document["certificate"]
    result = _solve(_reposed(certificate["data"], certificate["options"], 1.0, np.asarray(document["upgrade"])),
                    certificate["options"])
    assert all(stage["certified"] for stage in result["stages"]) and _valid(result)
    assert np.abs(np.asarray(result["K"]) - TRUTH).max() < 0.01


def test_a_calibration_certificate_solved_again_at_scale_one_verifies_with_the_genuine_K():
    forged = _calibration_forged(1.0)
    genuine = np.asarray(stored("reconstruction")["summary"]["calibration"]["certified_K"])
    assert np.abs(np.asarray(forged["summary"]["calibration"]["certified_K"]) - genuine).max() < 0.1
    assert _valid(forged)
