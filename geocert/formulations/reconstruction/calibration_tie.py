"""What ties a reconstruction's calibration certificate to the result carrying it (numpy only).

The calibration certificate proves its K optimal for the projective reconstruction in its own
data: the pipeline's, from the same tracks, which the returned cameras refine by bundle
adjustment. Its cameras must be the views the autocalibration stage names (certificate_views),
its points the tracks it names (certificate_tracks), every one of those views registered in the
result, and it must image every observation it
shares with the result's placed points where the returned cameras image it, to within TIE_RATIO
times the returned cameras' own RMS error on those observations, plus CONVERGENCE of the
observations' median coordinate (each observation's larger coordinate, their median: the largest
let one observation imaged far off, by a point just in front of a camera's principal plane, widen
every observation's allowance, from 3.9 px to 803 on the off-centre scene). A median distance, or a floor of 10 px, let half the observations lie
anywhere, or a reconstruction 8% off in focal length pass on tracks whose own error is 0.5 px. A
result that places no point has nothing to tie the certificate to (without_points): its certified
K is then claimed of the certificate's own reconstruction only, and the report says so.

CONVERGENCE is what the projective stage's own convergence leaves on tracks the returned cameras
fit exactly: on the kind's example (pixels rounded to 1e-6, the returned cameras' RMS error
3e-7 px) the two images of a shared observation are up to 0.020 px apart, 3.5e-5 of the largest
coordinate (571); 2e-4 (0.11 px there) leaves a margin of 5.8, and widens the allowance by about
what a focal length 0.05% off moves these images (8% moves the stored scene's up to 20 px).

The certificate's reconstruction must also fit the observations themselves: its squared error
on the shared observations at most the returned cameras' there (or, when held to the returned
reconstruction re-adjusted in its cameras' model, that one's where it is larger), plus
FIT_SIGMAS standard deviations of the chi-square over the d coordinates (sigma^2 sqrt(2 d),
sigma^2 estimated as the returned cameras' cost over d), plus MISFIT_SHARE of what that model
costs beyond the returned cameras (at most their cost), plus CONVERGENCE's floor for each
coordinate. A reconstruction re-posed with another K lies close to the returned cameras' images
of the observations yet fits the observations themselves worse: on the stored reconstruction (192
coordinates, 1.33 times allowed) a focal length 1.5 times the returned cameras' fits them at 7.3
times their cost, 1.2 times at 2.6. Genuine certificates, measured above that reference in
standard deviations: 0.0 (the stored scene, the synthetic scene with 100 tracks, every run
registered at the estimated principal point 30 to 186 px off centre, templeSparseRing's photos),
0.27 (the Oxford Model House's 1,255 observations), 1.3 (templeRing's 47 photos), below it (the Dinosaur's every 10th track: the returned cameras'
robust fit 28.7 px^2, the model's least 16.9, the certificate 28.7); certificates registered at
the image's centre while the tracks' principal point is 36, 36 and 75 px off: 1.0, 0.6 and 33
(188 px^2, 0.17 of the model's misfit, 1,137: MISFIT_SHARE covers it). A certificate of every
track re-posed at 1.05 (1.07) times the focal length at the returned principal point measures 16
(31) standard deviations on the (+30, -20) scene, 4.8 (8.8) on the Model House. Not covered: at
the image's centre the model's misfit gives a forger MISFIT_SHARE of it (1.05 times at (+30, -20):
84.5 px^2 above the model's least, 107.6 allowed; tied from 0.96 to 1.05 times there, 1.00 to 1.15 at (-60, +45),
whose genuine centred certificate certifies 1.07 times and uses 0.73 of the room: stated in the report's statement
and docs/certificate.md, not tightened).

Both tests assume the certificate's reconstruction is as free as the returned cameras' model.
An incremental registration's cameras (the default) are not: K [R | t] with one focal length,
square pixels, no skew and the principal point at each image's centre, while the returned
cameras estimate the principal point (and with camera_model "full" aspect and skew). On tracks
whose principal point is off the centre that model fits worse by what holding it there costs,
which grows with the square of the offset and which no noise allowance covers (36 px off on the
synthetic scene: 535.5 px^2 against 514.4 allowed, the returned cameras at 227.3). Such a
certificate (_built_centred, recomputed from its cameras) is held instead to the returned
reconstruction re-adjusted in its model (_centred_reference, centred_fit): in the pixel test, and
in the fit test with that reconstruction's cost beyond the returned cameras' added to the
allowance. The addition is measured, not a constant: the evaluated cost of an explicit
reconstruction in the model, so at least its least cost; the focal length free and the centre
the image's, so a certificate re-posed with another focal length or principal point gains
nothing from it.

The registration builds its cameras at the principal point the data fix when the returned
cameras estimate it (pipeline._registration_principal_point: held at the centre, 114 px off, the
pipeline's robust adjustment lay farther from that model's least-squares fit than the tie
allows). Cameras built with one K, square pixels and no skew whose principal point is not each
image's centre (_built_one_K) are held likewise to the returned reconstruction re-adjusted with
one focal length and one principal point, both free (centred_fit with no centres): its cost is
at most what holding the principal point anywhere costs, so a certificate re-posed with another
principal point than the data's pays its misfit without allowance; and that model costs beyond
the returned cameras what their freer model (a principal point or a focal length per view)
saves, which a certificate of one K, wherever it is built, cannot fit (the 15%-longer view's
scene with per-view principal points: an observation 4.31 px from the returned cameras' image,
3.8 allowed).

TIE_RATIO, measured on genuine results (the largest distance between the two images of a shared
observation over the returned cameras' RMS error there; docs/certificate.md): 0.03 on the stored
synthetic reconstruction, 0.90 on templeSparseRing's photos, 2.9 on the Oxford Corridor's and the
Oxford Dinosaur's tracks, 3.1 on the Oxford Model House's; a certificate of the stored scene's reconstruction with its
focal lengths scaled by 8%: 37. The pipeline's projective cameras are the registered cameras
before the adjustment, so what separates the two images is the adjustment's step; 10 leaves a
margin of 3 over the House.
"""

from __future__ import annotations

import math

import numpy as np

from geocert.core.strict import Invalid, numbers
from geocert.formulations.reconstruction import camera_claim, centred_fit
from geocert.formulations.reconstruction.calibration_claim import BUILT_WITH_ONE_K, camera_intrinsics

TIE_RATIO, TIE_OBSERVATIONS = 10.0, 12
# Each certificate camera of a registered view must image at least this many of the result's
# placed points where the returned camera does: a 3x4 camera has 11 degrees of freedom, so fewer leave it (and the K
# certified from it) free; two shared points per camera let a genuine certificate of another
# reconstruction, 1.5 times the focal length, pass on 12 observations.
TIE_POINTS_PER_CAMERA = 6
CONVERGENCE = 2e-4  # relative to the observations' median coordinate (above)
FIT_SIGMAS = 3.0  # the fit's allowance (above): standard deviations of a chi-square over the coordinates
MISFIT_SHARE = 0.25  # the fit's allowance (above): of what the certificate's model costs beyond the returned cameras
# The other tracks' cost in a genuine certificate's cameras (_other_tracks), over the returned cameras' times the
# model's ratio, in standard deviations of a chi-square over their coordinates: the synthetic (+30, -20) scene of 200
# tracks with 40 (20) held 0.00 (0.00), centred 0.00, (-60, +45) 0.00; the Oxford Model House (60 of its tracks held)
# 0.12; the Oxford Dinosaur's every 10th track (20 asked for, 66 held) 0.01. FIT_SIGMAS (3) leaves a margin of 25.
# Registered at the image's centre (the pipeline before issue 35, the model's ratio 2.25 and 2.33), the (+30, -20)
# scene with 20 (40) tracks held: 1.03 (0.97) times the returned cost times the ratio, 0.86 (0.81) of the allowance.
OTHER_TRACKS_MEASURED = {"synthetic": 0.00, "model_house": 0.12, "dinosaur": 0.01}


def tie(result: dict, stage: dict, data: dict, recorded: bool = True) -> dict:
    """Refuses a calibration certificate whose reconstruction is not the result's (as above);
    returns the figures the report's scope states of the tie. ``recorded``: whether the document's
    form states the registration's principal-point record wherever its test runs
    (verify.hashed_options.states_records; an earlier form's may lack it)."""
    views, tracks = stage.get("certificate_views"), stage.get("certificate_tracks")
    cameras = numbers(data.get("cameras"), "calibration_certificate/data/cameras", (None, 3, 4), "returned")
    points = numbers(data.get("points"), "calibration_certificate/data/points", (None, 4), "returned")
    n_views = len(result["cameras"])
    if not (isinstance(views, list) and isinstance(tracks, list) and len(views) == len(cameras) == len(set(views))
            and len(tracks) == len(points) == len(set(tracks))
            and all(isinstance(v, int) and 0 <= v < n_views for v in views)
            and all(isinstance(t, int) and t >= 0 for t in tracks)):
        raise Invalid("returned", "stages/autocalibration must name the view of each calibration certificate camera "
                                  "and the track of each point (certificate_views, certificate_tracks)")
    # The stage's count of the points the autocalibration used is the certificate's (both are the
    # points upgrade.autocalibrate chose): a count beside the certificate that states it is tied to it.
    if "points_used" in stage and stage["points_used"] != len(points):
        raise Invalid("returned", f"stages/autocalibration/points_used {stage['points_used']!r:.40} is not the "
                                  f"calibration certificate's {len(points)} points")
    size = data.get("image_size")
    if size is not None and any(camera.get("image_size") not in (None, list(size)) for camera in result["cameras"]
                                if camera.get("view") in views):
        raise Invalid("returned", "the calibration certificate's image_size is not its views'")
    # A view the result does not register (dropped after the calibration) has no returned camera
    # to tie its certificate camera to: a camera tied to nothing, which moves the certified K as
    # freely as it is placed (the pipeline carries no certificate then).
    registered = {int(c["view"]) for c in result["cameras"] if c.get("registered") is True}
    untied = [view for view in views if view not in registered]
    if untied:
        raise Invalid("returned", f"the calibration certificate holds a camera of view {untied[0]}, which the result "
                                  "does not register: nothing ties it to the result")
    registration = _check_registration_record(result, views, cameras, recorded)
    if not any(point.get("point") is not None for point in result["points"]):
        return {**without_points(views, tracks), "registration_record": registration}
    apart, own, theirs, largest, per_camera, at = _shared(result, views, tracks, cameras, points)
    loose = [view for view, count in zip(views, per_camera) if count < TIE_POINTS_PER_CAMERA]
    if loose:
        raise Invalid("returned", f"the calibration certificate's camera of view {loose[0]} images "
                                  f"{per_camera[views.index(loose[0])]} of the result's placed points (each of its cameras "
                                  f"must be tied by at least {TIE_POINTS_PER_CAMERA}: fewer leave it, and the K "
                                  "certified from it, free)")
    if len(apart) < TIE_OBSERVATIONS:
        raise Invalid("returned", f"the calibration certificate's reconstruction shares {len(apart)} observations "
                                  f"with the result's placed points (at least {TIE_OBSERVATIONS} tie it to them)")
    rms = math.sqrt(float(np.mean(np.square(own))))
    centred = _centred_reference(result, views, cameras, at)
    where = "the returned cameras"
    if centred is not None:  # an incremental registration's cameras: held to the returned ones re-adjusted in their model
        apart = [math.hypot(*(mine - ref)) for mine, ref in zip(at[1], centred[0])]
        where = "the returned reconstruction re-adjusted in its cameras' model"
    apart = np.nan_to_num(np.asarray(apart), nan=np.inf)
    allowed = TIE_RATIO * rms + CONVERGENCE * largest
    worst = float(np.max(apart))
    if not worst <= allowed:
        raise Invalid("returned", f"the calibration certificate's reconstruction images an observation {worst:.3g} px "
                                  f"from where {where} does (at most {allowed:.3g}: {TIE_RATIO:g} times "
                                  f"their RMS error {rms:.3g} px on the {len(apart)} observations shared, plus "
                                  f"{CONVERGENCE:g} of the median coordinate {largest:.4g}): it is not "
                                  "these tracks' reconstruction")
    fit = _fit(own, theirs, largest, None if centred is None else centred[1])
    # what the certificate's model costs beyond the returned cameras' on the shared observations, as
    # a ratio (1 when held to the returned cameras): its cameras cost as much more on the others
    returned = float(np.sum(np.square(own)))
    ratio = 1.0 if centred is None or not returned > 0 else max(1.0, centred[1] / returned)
    others = _other_tracks(result, views, tracks, cameras, ratio)
    return {"reference": "the returned cameras" if centred is None else centred[2],
            "observations": len(apart), "largest_px": worst, "allowed_px": allowed, "returned_rms_px": rms,
            "fewest_points_per_camera": min(per_camera, default=0), **fit, **others,
            "registration_record": registration}


def registration_tests(result: dict) -> bool:
    """Whether the pipeline's registration tests the principal point in this run, and so states
    its record (pipeline._registration_principal_point): K unknown, the incremental registration,
    the adjustment run and estimating the principal point (camera_model "full", or "simple" with
    principal_point "auto" or "per_view"), every view of one image size (the certificate data's
    input_labels, else the cameras'), no radial term kept, and the registration not stopped. The
    options are read from the echo, absent as ReconstructionOptions' defaults (the hash covers
    them all in the form that states the record)."""
    certificate = result.get("certificate") or {}
    options = certificate.get("options") or {}
    intrinsics = options.get("intrinsics")
    if isinstance(intrinsics, dict) and intrinsics.get("K") is not None:
        return False
    model, principal = options.get("camera_model", "simple"), options.get("principal_point", "per_view")
    if options.get("registration", "incremental") != "incremental" or options.get("bundle_adjustment", True) is not True \
            or not (model == "full" or (model == "simple" and principal in ("auto", "per_view"))):
        return False
    labels = (certificate.get("data") or {}).get("input_labels")
    sizes = labels.get("image_sizes") if isinstance(labels, dict) else None
    if not isinstance(sizes, list):
        sizes = [camera.get("image_size") for camera in result.get("cameras") or [] if isinstance(camera, dict)]
    if not sizes or not all(isinstance(size, list) for size in sizes) \
            or len({tuple(float(x) for x in size) for size in sizes}) != 1:
        return False
    projective = next((s for s in result.get("stages") or [] if isinstance(s, dict) and s.get("name") == "projective"),
                      {})
    radial = projective.get("radial_distortion")
    stopped = projective.get("cancelled") is True or projective.get("status") in ("cancelled", "time_limit")
    return not (isinstance(radial, dict) and radial.get("estimated") is True) and not stopped


def _check_registration_record(result: dict, views: list, cameras: np.ndarray, recorded: bool = True) -> str:
    """The projective stage's principal-point record (pipeline._registration_principal_point) and
    the certificate's cameras, which are the registration's, say the same thing: cameras built with
    one K whose principal point is not every view's image centre (_built_one_K, not _built_centred)
    only where the record says the principal point was estimated (the views of one image size, as
    the registration tests it only then); and a record saying so only
    beside cameras built with one K, that K its K_free (the registration kept the free fit's
    cameras). Unchecked, the record was the document's word: on the (+30, -20) off-centre run it
    verified saying the principal point was held at the centre (estimated false), or with no record,
    or with K_free moved to the centre or to another focal length, its certificate's cameras built
    at (349.2, 219.8). And the record is stated wherever this run's registration tests the principal
    point (registration_tests) when ``recorded`` (the document's form states it so): without it,
    cameras built at the images' centre beside off-centre tracks got the centred reference's room
    (a certificate re-posed with another focal length tied from 0.96 to 1.05 times). Returns what
    the report's scope says of the record."""
    record = _registration_record(result)
    tested = registration_tests(result)
    if record is None and tested and recorded:
        # Without the record the certificate's cameras would be read as a registration at the
        # images' centre, held to the centred reference with its room (MISFIT_SHARE): a document of
        # a form that states the record may not choose that reading by leaving it out.
        raise Invalid("returned", "stages/projective/principal_point is absent, and this run's registration tests "
                                  "the principal point (the incremental registration, the adjustment estimating it, "
                                  "views of one image size, no radial term kept, not stopped): a document of this "
                                  "form (its problem_sha256 covers registration) states that record wherever the "
                                  "test runs, and without it the certificate's cameras would be read as built at "
                                  "the images' centre, with that reference's room")
    estimated = isinstance(record, dict) and record.get("estimated") is True
    one_K = _built_one_K(cameras)
    sizes = {tuple(c["image_size"]) for c in result["cameras"] if c.get("view") in views
             and isinstance(c.get("image_size"), list)}
    # (views of several sizes: the registration does not test the principal point, and its one K
    # cannot be every view's centre)
    if one_K and not estimated and len(sizes) == 1 and not _built_centred(result, views, cameras):
        raise Invalid("returned", "the calibration certificate's cameras are built with one K whose principal point is "
                                  "not the images' centre, and stages/projective/principal_point does not say the "
                                  "registration estimated it (the registration builds its cameras at the centre "
                                  "unless its test estimates the principal point)")
    if not estimated:
        if record is not None:
            return "stated"
        return ("absent: this run's registration does not test the principal point" if not tested else
                "absent: the document is of an earlier form (its problem_sha256 does not cover registration), "
                "written before the registration's principal-point test was always stated, so its certificate's "
                "cameras are read without it (built at the images' centre, the centred reference's room)")
    try:
        K_free = np.asarray(record.get("K_free"), dtype=float).reshape(3, 3)
    except (TypeError, ValueError):
        K_free = np.full((3, 3), np.nan)
    K = camera_intrinsics(cameras[0]) if one_K else None
    if K is None or not np.all(np.isfinite(K_free)) or not np.all(
            np.abs(K - K_free) <= BUILT_WITH_ONE_K * float(np.abs(K).max())):
        raise Invalid("returned", "stages/projective/principal_point says the registration estimated the principal "
                                  "point (its cameras built with the free fit's K, K_free), and the calibration "
                                  "certificate's cameras are not built with one K equal to its K_free")
    return "stated"


def without_points(views: list, tracks: list) -> dict:
    """The tie of a result that places no point (a run stopped after the certified upgrade and
    before the structure stage returned one: a cancel, the job's clock, the structure stage's own):
    no observation of the result's is there to tie the certificate's reconstruction to, and none
    to contradict it. The certificate proves its K optimal for the reconstruction in its own data
    only (which the verifier checks from that data alone: ReconstructionItems.check_result asks
    that the result claim that K certified, so that its certificate is verified), and the figures
    say that nothing tied it: no observation, no point per camera."""
    return {"observations": 0, "tied": False, "views": len(views), "tracks": len(tracks),
            "fewest_points_per_camera": 0,
            "statement": "the result places no point: the calibration certificate's K is proven optimal for the "
                         "projective reconstruction in its own data only, which nothing in the result ties to its "
                         "tracks"}


def _fit(own: list, theirs: list, largest: float, model: float | None = None) -> dict:
    """Refuses a certificate whose reconstruction fits the shared observations worse than the
    noise allows (FIT_SIGMAS, above), plus, when its cameras are an incremental registration's
    (``model``: the cost of the returned reconstruction re-adjusted in their model on the shared
    observations, _centred_reference), what that model costs beyond the returned cameras; returns
    the figures the scope states of it."""
    coordinates = 2 * len(own)
    returned = float(np.sum(np.square(own)))
    cost = float(np.sum(np.square(np.nan_to_num(np.asarray(theirs, dtype=float), nan=np.inf))))
    # The noise's allowance is the returned cameras' (as it always was); the model's cost beyond it
    # is not a constant but the evaluated cost of a reconstruction of these observations in the
    # certificate's own camera model (centred_fit: at least that model's least cost, so a genuine
    # certificate is not asked for better, and its focal length free, so a reconstruction re-posed
    # with another focal length gains nothing from it).
    # The reference is the better fit of the two explicit reconstructions of these observations,
    # the returned cameras and the one in the certificate's model (each at least its own model's
    # least; the returned cameras' robust fit can lie above the model's least-squares one: 28.7
    # px^2 against 16.9 on the Dinosaur's every 10th track). The allowance beyond it is the
    # noise's, FIT_SIGMAS standard deviations of the chi-square over the coordinates (sigma^2
    # sqrt(2 d), sigma^2 the returned cost over d), plus MISFIT_SHARE of what the model costs
    # beyond the returned cameras, never more than their cost (the whole of which was the slack
    # before, and let a certificate re-posed at 1.07 times the focal length verify).
    misfit = 0.0 if model is None else max(0.0, model - returned)
    sd = returned * math.sqrt(2.0 / coordinates)
    allowed = (returned + misfit + FIT_SIGMAS * sd + min(returned, MISFIT_SHARE * misfit)
               + coordinates * (CONVERGENCE * largest) ** 2)
    if not cost <= allowed:
        raise Invalid("returned", f"the calibration certificate's reconstruction fits the {len(own)} observations it "
                                  f"shares with the result at a cost of {cost:.4g} px^2, the returned cameras at "
                                  f"{returned:.4g} (at most {allowed:.4g}: theirs"
                                  + ("" if model is None else f" plus {misfit:.4g} that its cameras' model costs the "
                                                              f"returned reconstruction re-adjusted in it, and "
                                                              f"{MISFIT_SHARE:g} of that")
                                  + f" plus {FIT_SIGMAS:g} standard deviations of a chi-square over its "
                                  f"{coordinates} coordinates"
                                  + "): it is not a reconstruction of these tracks' observations")
    figures = {"shared_cost_px2": cost, "returned_cost_px2": returned, "allowed_cost_px2": allowed}
    if model is not None:
        figures["model_cost_px2"] = model
    return figures


def _shared(result: dict, views: list, tracks: list, cameras: np.ndarray, points: np.ndarray
            ) -> tuple[list, list, list, float, list[int], tuple[list, list]]:
    """For each observation of a placed point in a registered view that the certificate's data
    hold too: the distance between its images through the certificate's camera and point and
    through the returned ones, the returned ones' error and the certificate's; the median of
    each observation's larger coordinate (not the largest: one observation far off would widen
    all); how many such points each certificate camera images; and where each shared
    observation is ((its point's index in the result, its view), and its certificate image)."""
    camera_of, point_of = {v: k for k, v in enumerate(views)}, {t: k for k, t in enumerate(tracks)}
    by_view = {int(c["view"]): np.asarray(c["P"], dtype=float) for c in result["cameras"] if c.get("P") is not None}
    apart, own, theirs, scales = [], [], [], []
    keys, images = [], []
    per_camera = [set() for _ in views]
    least = _least_points(result, point_of, by_view)
    for index, point in enumerate(result["points"]):
        j = point_of.get(point.get("track"))
        if j is None or point.get("point") is None:
            continue
        X = least.get(index)
        if X is None:
            X = np.asarray(point["point"] if point.get("at_infinity") else [*point["point"], 1.0], dtype=float)
        for view, u, v in point.get("observations") or []:
            i = camera_of.get(int(view))
            if i is None or int(view) not in by_view:
                continue
            with np.errstate(all="ignore"):
                x, y = cameras[i] @ points[j], by_view[int(view)] @ X
                apart.append(math.hypot(x[0] / x[2] - y[0] / y[2], x[1] / x[2] - y[1] / y[2]))
                own.append(math.hypot(y[0] / y[2] - u, y[1] / y[2] - v))
                theirs.append(math.hypot(x[0] / x[2] - u, x[1] / x[2] - v))
                images.append(x[:2] / x[2])
            keys.append((index, int(view)))
            per_camera[i].add(j)
            scales.append(max(abs(float(u)), abs(float(v))))
    largest = float(np.median(scales)) if scales else 0.0
    return apart, own, theirs, largest, [len(seen) for seen in per_camera], (keys, images)


def _least_points(result: dict, point_of: dict, by_view: dict) -> dict:
    """Each placed point the certificate holds, seen by at least 2 views with a returned camera,
    triangulated in the returned cameras from all its observations there (_triangulate), by its
    index in the result: the returned cameras are held to their own least on these tracks, not to
    the points as stated. A point not certified is the result's to place, and one placed off its
    least widened the tie by its error: 10 such points (L1L1, max_nodes 1: every point node_limit,
    each residual within max_residual 20) made the returned cameras' cost 28,736 px^2 on the
    shared observations (227 at their least; 254 at the genuine run's L1-optimal points), and a
    certificate re-posed at 1.3 times the focal length (2,679 px^2, 4.1 px off) was tied and the
    document verified."""
    P, group, uv, index, stated = [], [], [], [], []
    for k, point in enumerate(result["points"]):
        if point.get("point") is None or point.get("track") not in point_of:
            continue
        seen = [(int(v), float(u), float(w)) for v, u, w in point.get("observations") or [] if int(v) in by_view]
        if len(seen) < 2:
            continue
        for v, u, w in seen:
            P.append(by_view[v]), group.append(len(index)), uv.append((u, w))
        index.append(k)
        stated.append(point["point"] if point.get("at_infinity") else [*point["point"], 1.0])
    if not index:
        return {}
    P, group, uv = np.asarray(P, dtype=float), np.asarray(group), np.asarray(uv, dtype=float)
    X, errors = _triangulate(P, group, uv)
    # the stated point where it fits better (the triangulation's is an evaluated cost, not the least)
    given = np.asarray(stated, dtype=float)
    better = np.bincount(group, _errors(P, given[group], uv), minlength=len(index)) \
        < np.bincount(group, errors, minlength=len(index))
    X = np.where(better[:, None], given, X)
    return {k: X[m] for m, k in enumerate(index) if np.all(np.isfinite(X[m]))}


def _other_tracks(result: dict, views: list, tracks: list, cameras: np.ndarray, ratio: float) -> dict:
    """The certificate's cameras must explain the result's other tracks too: the placed points it
    holds no point for, each seen by at least 2 of its views. The certificate chooses its tracks,
    and a few can leave K free: 6 tracks of points at the scene's middle (their images 200 px
    across, the result's 200 tracks) let a certificate re-posed at twice the focal length (or 0.7
    times) image every shared observation within 0.81 px of the re-adjusted reconstruction's images
    and fit them at 10.1 px^2 (22.8 allowed): tied by them alone, it verified. Each other point is
    triangulated in the certificate's cameras and in the returned ones (_triangulated), and the
    certificate's cost on those observations must be at most the returned cameras' times
    ``ratio`` (what the certificate's model costs beyond theirs on the shared observations, at
    least 1: the model's cost measured where the tie measures it, and the pipeline's certificate
    holds a spread of the tracks) plus MISFIT_SHARE of what that ratio adds (at most their cost),
    FIT_SIGMAS standard deviations of a chi-square over their coordinates and CONVERGENCE's floor
    for each: the allowance _fit gives the shared observations. Twice their cost was allowed
    before, and a certificate of 6 (12, 20) middle tracks, its cameras re-posed at 1.08 times the
    focal length and fitted to every track, passed the tie (445 px^2 against 471 allowed; now 246).
    Genuine certificates measured (OTHER_TRACKS_MEASURED): within 0.12 standard deviations of the
    returned cameras' cost times ``ratio``. Returns the figures the scope states."""
    reference = {int(c["view"]): np.asarray(c["P"], dtype=float) for c in result["cameras"]
                 if c.get("registered") is True and c.get("P") is not None}
    camera_of = {v: k for k, v in enumerate(views)}
    held = set(tracks)
    mine, theirs, pixels, counts, stated = [], [], [], [], []
    for point in result["points"]:
        if point.get("point") is None or point.get("track") in held:
            continue
        seen = [(int(v), float(u), float(w)) for v, u, w in point.get("observations") or []
                if int(v) in camera_of and int(v) in reference]
        if len(seen) < 2:
            continue
        counts.append(len(seen))
        stated.append(point["point"] if point.get("at_infinity") else [*point["point"], 1.0])
        for v, u, w in seen:
            mine.append(cameras[camera_of[v]]), theirs.append(reference[v]), pixels.append((u, w))
    if not pixels:
        return {"other_observations": 0}
    group = np.repeat(np.arange(len(counts)), counts)
    uv = np.asarray(pixels, dtype=float)
    cost = float(np.sum(_triangulated(np.asarray(mine, dtype=float), group, uv)))
    theirs = np.asarray(theirs, dtype=float)
    # the returned cameras at the better of each point's triangulation in them and the point stated
    base = float(np.sum(np.minimum(np.bincount(group, _triangulated(theirs, group, uv)),
                                   np.bincount(group, _errors(theirs, np.asarray(stated, dtype=float)[group], uv)))))
    coordinates = 2 * len(uv)
    floor = float(np.median(np.max(np.abs(uv), axis=1)))
    # the noise's allowance, as the shared observations' (_fit): FIT_SIGMAS standard deviations
    # of the chi-square, and MISFIT_SHARE of what the certificate's model costs beyond the returned
    # cameras (at most their cost); not twice their cost, which let a certificate re-posed at 1.08
    # times the focal length pass
    allowed = (base * (ratio + min(1.0, MISFIT_SHARE * (ratio - 1.0)) + FIT_SIGMAS * math.sqrt(2.0 / coordinates))
               + coordinates * (CONVERGENCE * floor) ** 2)
    if not cost <= allowed:
        raise Invalid("returned", f"the calibration certificate's cameras fit the {len(uv)} observations of the "
                                  f"result's {len(counts)} placed points it holds no point for (each triangulated "
                                  f"in them) at a cost of {cost:.4g} px^2, the returned cameras at {base:.4g} "
                                  f"(at most {allowed:.4g}: theirs times {ratio:.4g}, what the certificate's "
                                  f"model costs beyond them on the shared observations, plus {MISFIT_SHARE:g} of "
                                  f"that excess and {FIT_SIGMAS:g} standard deviations of a chi-square over the {coordinates} coordinates): they "
                                  "are not these tracks' cameras")
    return {"other_observations": len(uv), "other_cost_px2": cost, "other_returned_cost_px2": base,
            "other_allowed_cost_px2": allowed}


TRIANGULATION_STEPS = 20  # Levenberg-Marquardt steps per point (from the linear estimate)


def _errors(P: np.ndarray, X: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Each observation's squared reprojection error (px^2) in the camera P (one 3x4 each) of the
    homogeneous point X (one each); infinite where it is not finite."""
    with np.errstate(all="ignore"):
        x = np.einsum("kij,kj->ki", P, X)
        e = np.sum(np.square(x[:, :2] / x[:, 2:3] - uv), axis=1)
    return np.where(np.isfinite(e), e, np.inf)


def _triangulated(P: np.ndarray, group: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Each observation's squared reprojection error (px^2) with its point (``group``) triangulated
    in the cameras ``P`` (one 3x4 per observation): _triangulate's."""
    return _triangulate(P, group, uv)[1]


def _triangulate(P: np.ndarray, group: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each point (``group``) triangulated in the cameras ``P`` (one 3x4 per observation) from its
    observations ``uv``: the linear estimate, then Levenberg-Marquardt steps on the unit sphere of
    homogeneous points (a point at infinity as any other), each point's step kept only where it
    lowers its cost; the points (homogeneous, unit) and each observation's squared error (px^2).
    An evaluated cost: at least the point's least (a certificate is never favoured by it);
    infinite where it is not finite."""
    n = int(group.max()) + 1
    with np.errstate(all="ignore"):
        A = np.concatenate([uv[:, :1] * P[:, 2] - P[:, 0], uv[:, 1:] * P[:, 2] - P[:, 1]], axis=0)
        A = A / np.maximum(np.linalg.norm(A, axis=1, keepdims=True), 1e-300)
        rows = np.concatenate([group, group])
        AtA = np.zeros((n, 4, 4))
        np.add.at(AtA, rows, A[:, :, None] * A[:, None, :])
        if not np.all(np.isfinite(AtA)):
            return np.full((n, 4), np.nan), np.full(len(uv), np.inf)
        X = np.linalg.eigh(AtA)[1][:, :, 0]  # (n, 4), unit

        def errors(X):
            x = np.einsum("kij,kj->ki", P, X[group])
            r = x[:, :2] / x[:, 2:3] - uv
            e = np.sum(r * r, axis=1)
            return np.where(np.isfinite(e), e, np.inf), x, r

        e, x, r = errors(X)
        per_point = np.bincount(group, e, minlength=n)
        lam = np.full(n, 1e-3)
        for _ in range(TRIANGULATION_STEPS):
            # a basis of the tangent space at X (the 3 directions orthogonal to it)
            B = np.linalg.svd(X[:, None, :])[2][:, 1:, :].transpose(0, 2, 1)  # (n, 4, 3)
            PB = P @ B[group]  # (M, 3, 3)
            z = x[:, 2:3]
            J = (PB[:, :2, :] * z[:, :, None] - x[:, :2, None] * PB[:, 2:3, :]) / (z[:, :, None] ** 2)  # (M, 2, 3)
            H = np.zeros((n, 3, 3))
            np.add.at(H, group, J.transpose(0, 2, 1) @ J)
            g = np.zeros((n, 3))
            np.add.at(g, group, (J.transpose(0, 2, 1) @ r[:, :, None])[:, :, 0])
            damped = H + lam[:, None, None] * (np.einsum("pii->pi", H)[:, :, None] * np.eye(3) + 1e-12 * np.eye(3))
            ok = np.all(np.isfinite(damped), axis=(1, 2)) & np.all(np.isfinite(g), axis=1)
            step = np.zeros((n, 3))
            try:
                step[ok] = -np.linalg.solve(damped[ok], g[ok][:, :, None])[:, :, 0]
            except np.linalg.LinAlgError:
                break
            trial = X + np.einsum("pij,pj->pi", B, step)
            trial = trial / np.linalg.norm(trial, axis=1, keepdims=True)
            e_trial, x_trial, r_trial = errors(trial)
            better = np.bincount(group, e_trial, minlength=n) < per_point
            X = np.where(better[:, None], trial, X)
            lam = np.where(better, lam / 3, lam * 5)
            e, x, r = errors(X)
            per_point = np.bincount(group, e, minlength=n)
    return X, e


CENTRED_REFERENCE = ("the returned reconstruction re-adjusted with one focal length, square pixels, no skew and the "
                     "principal point at each image's centre: the model the certificate's cameras are built in")
ONE_K_REFERENCE = ("the returned reconstruction re-adjusted with one focal length and one principal point (both free), "
                   "square pixels and no skew: the model the certificate's cameras are built in")


CENTRED_HELD = ("the returned reconstruction re-adjusted with one focal length and one principal point (both free), "
                "square pixels and no skew: the certificate's cameras are built at the images' centre, the "
                "registration's record is stated, and that re-adjustment (the verifier's own) puts the principal "
                "point inside the images' middle half, where the registration holds it at the centre only when its "
                "test does not pass: holding it there is given no room")


def _built_centred(result: dict, views: list, cameras: np.ndarray) -> bool:
    """Whether every certificate camera is K [R | t] with one focal length, square pixels, no skew
    and the principal point at its view's image centre ((w - 1) / 2, (h - 1) / 2), to
    calibration_claim.BUILT_WITH_ONE_K of K's largest entry: the incremental registration's cameras."""
    sizes = {c.get("view"): c.get("image_size") for c in result["cameras"]}
    focals = []
    for view, P in zip(views, cameras):
        size = sizes.get(view)
        if not (isinstance(size, list) and len(size) == 2 and all(isinstance(s, (int, float)) and not isinstance(s, bool)
                                                                   and 0 < s < 1e9 for s in size)):
            return False
        K = camera_intrinsics(P)
        if K is None:
            return False
        tol = BUILT_WITH_ONE_K * float(np.abs(K).max())
        if not (np.all(np.isfinite(K)) and abs(K[0, 1]) <= tol and abs(K[1, 1] - K[0, 0]) <= tol
                and abs(K[0, 2] - (size[0] - 1) / 2) <= tol and abs(K[1, 2] - (size[1] - 1) / 2) <= tol):
            return False
        focals.append(float(K[0, 0]))
    return bool(focals) and max(focals) - min(focals) <= BUILT_WITH_ONE_K * max(focals)


def _built_one_K(cameras: np.ndarray) -> bool:
    """Whether every certificate camera is K [R | t] with one K (its principal point anywhere),
    square pixels and no skew, to calibration_claim.BUILT_WITH_ONE_K of K's largest entry: the
    registration's cameras built at the principal point the data fix."""
    Ks = [camera_intrinsics(P) for P in cameras]
    if not Ks or any(K is None or not np.all(np.isfinite(K)) for K in Ks):
        return False
    tol = BUILT_WITH_ONE_K * float(np.abs(Ks[0]).max())
    return all(abs(K[0, 1]) <= tol and abs(K[1, 1] - K[0, 0]) <= tol and np.all(np.abs(K - Ks[0]) <= tol)
               for K in Ks)


def _registration_record(result: dict):
    """The projective stage's principal-point record (pipeline._registration_principal_point), or None."""
    return next((s.get("principal_point") for s in result.get("stages") or []
                 if isinstance(s, dict) and s.get("name") == "projective"), None)


def _outside_middle_half(result: dict, views: list, principal: np.ndarray) -> bool:
    """Whether ``principal`` (one principal point, px) lies outside the middle half of the views'
    one image size, as pipeline._principal_point judges its free fit's (|u - w/2| > w/4 or
    |v - h/2| > h/4); False where the views have no one size (the registration tests the principal
    point only then)."""
    sizes = {tuple(c["image_size"]) for c in result["cameras"] if c.get("view") in views
             and isinstance(c.get("image_size"), list) and len(c["image_size"]) == 2}
    if len(sizes) != 1:
        return False
    (width, height), = sizes
    return not camera_claim.in_middle_half(float(principal[0]), float(principal[1]), width, height)


def _centred_reference(result: dict, views: list, cameras: np.ndarray, at: tuple[list, list]
                       ) -> tuple[list, float, str] | None:
    """When the certificate's cameras are an incremental registration's (_built_centred): the
    images of the shared observations (``at``'s order) in the returned reconstruction re-adjusted in
    that model (centred_fit.fit, over the shared observations only: the ones the tie measures, whose
    returned cost it compares; observations of other points, which no returned cost here answers
    for, pulled the fit, and its focal length, where a certificate re-posed at 1.23 times the focal
    length followed it), and its cost on them (px^2), and the reference's words; when they are
    built with one K, square pixels and no skew elsewhere (_built_one_K), the same with the
    principal point one and free; else None, and the certificate is held to the returned cameras
    (a projective reconstruction's cameras are as free as any model's).

    The centred reference (CENTRED_REFERENCE), whose cost beyond the returned cameras is the room a
    registration held at the images' centre needs on tracks whose principal point lies elsewhere,
    is the certificate's only where no record of the registration's test is stated (the test does
    not run, which the hashed options decide, or the document's form predates the record:
    _check_registration_record), or where the verifier's own re-adjustment with one principal point
    free puts it outside the images' middle half (where the registration holds it at the centre
    whatever its chi2). Elsewhere the certificate is held to that re-adjustment (CENTRED_HELD, no
    room): the registration held the principal point at the centre there only because its test did
    not pass, and holding it there then costs less than the threshold's noise variances, which the
    noise allowance covers. No member of the record chooses the reading: its chi2 and observations
    are the adjustment's figures, which the verifier cannot recompute, and its K_free is tied to
    the certificate's cameras only where it says estimated. Read from them, an edited chi2 (review
    26: the centred certificate at 1.03 times the focal length, the (+30, -20) scene, beside a chi2
    of 1.0) or K_free moved out of the middle half beside estimated false (review 29: 0.97 to 1.03
    times) chose the room, and the certificate verified."""
    if _built_centred(result, views, cameras):
        reference = CENTRED_REFERENCE if _registration_record(result) is None else CENTRED_HELD
    elif _built_one_K(cameras):
        reference = ONE_K_REFERENCE
    else:
        return None
    shared = set(at[0])
    registered = [c for c in result["cameras"] if c.get("registered") is True and c.get("P") is not None
                  and c.get("view") in views]
    index = {int(c["view"]): k for k, c in enumerate(registered)}
    X, view, point, uv, row = [], [], [], [], {}
    try:  # (the fields' shapes are checked elsewhere; one unreadable here leaves the returned cameras the reference)
        P = np.array([np.asarray(c["P"], dtype=float) for c in registered]).reshape(len(registered), 3, 4)
        centres = np.array([[(c["image_size"][0] - 1) / 2, (c["image_size"][1] - 1) / 2] for c in registered],
                           dtype=float) if reference != ONE_K_REFERENCE else None
        for k, p in enumerate(result["points"]):
            if p.get("point") is None:
                continue
            seen = [(int(v), u, w) for v, u, w in p.get("observations") or [] if (k, int(v)) in shared]
            if not seen:
                continue
            X.append(p["point"] if p.get("at_infinity") else [*p["point"], 1.0])
            for v, u, w in seen:
                row[(k, v)] = len(uv)
                view.append(index[v]), point.append(len(X) - 1), uv.append((u, w))
        X, uv = np.asarray(X, dtype=float).reshape(-1, 4), np.asarray(uv, dtype=float).reshape(-1, 2)
    except (TypeError, ValueError, KeyError, IndexError):
        return None
    view, point = np.asarray(view, dtype=int), np.asarray(point, dtype=int)
    if reference == CENTRED_HELD:
        free = centred_fit.fit_with_intrinsics(P, None, X, view, point, uv)
        if free is None:
            return None
        images = free[0]
        if _outside_middle_half(result, views, free[1][1:]):
            reference, images = CENTRED_REFERENCE, centred_fit.fit(P, centres, X, view, point, uv)
    else:
        images = centred_fit.fit(P, None if reference == ONE_K_REFERENCE else centres, X, view, point, uv)
    if images is None:
        return None
    keys = at[0]
    mine = images[[row[key] for key in keys]]
    pixels = np.asarray(uv, dtype=float)[[row[key] for key in keys]]
    return list(mine), float(np.sum(np.square(mine - pixels))), reference
