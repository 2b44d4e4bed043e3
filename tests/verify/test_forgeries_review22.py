"""Review 22 (issue 33): a hostile review of the calibration tie's centred fit, the per-view focal
length model and the L1 resection centre.

Found (verified on main, each test below failing there): the calibration certificate chooses its
tracks (certificate_tracks), and the tie measured only the observations of those. A few tracks of
points at the scene's middle leave the focal length free: on the (+30, -20) off-centre run (200
tracks, 8 views), a certificate holding 6 of them, its cameras re-posed at twice the returned
focal length (or 0.7 times), imaged each of their 48 observations within 0.81 px of the
re-adjusted reconstruction's images (4.44 allowed) and fitted them at 10.1 px^2 (22.8 allowed):
the whole document verified, certified_K 1599 px (the tracks' 800), determined. A forger who
adjusts the certificate's cameras to every track with K held passed the tie at 1.1 and 1.5 times
too. The tie now also reads the result's other placed points in the certificate's cameras
(calibration_tie._other_tracks: each triangulated there and in the returned cameras).

Found (verified on main, the test failing there): the tie measured the returned cameras at the
points as the result states them, and a point not certified is the result's to place (its cost
recomputed, honestly stated). Under L1L1, max_residual 20, max_nodes 1 (every point node_limit),
10 points moved within max_residual made the returned cameras' cost on the shared observations
28,736 px^2 (227 at their least) and their RMS 4.2 px: a certificate re-posed at 1.3 times the
focal length verified beside them (certified_K 1039.5 px). The returned cameras are now held to
their own least on each shared track (calibration_tie._least_points).

Tried and not passing (guards below, passing on main as here):
- the centred fit started from the per-view model's gauge family: with 3 views, a principal point
  each and one view's own focal length, 7 constraints leave a 1-parameter family of projective
  frames with every image the same (returned focal lengths from 126 to 2051 px); the fit converged
  to the same least cost (55.60 px^2) from every member tried (focal lengths 0 < f < 2051 px; only
  the degenerate limit f -> 0, cameras of focal length 0.004 px, stalled);
- a 100-view document of 50,000 observations at the pairs bound: one fit, 15 s of CPU, declined;
- per-view focal lengths claimed for views the data do not support: the record's chi2 and sd
  figures are the document's word (stated as such), the cameras' degrees of freedom grow (a smaller
  allowance: stricter), and the tie and the centred fit hold one focal length whatever the record;
- the L1 resection centre (proof.sublevel.centre): read (the dual bound, the enclosure and the
  weights), no new class tried beyond review 21's guard, which stands.

Found after (issue 33): a certificate holding every track, re-posed at 1.07 (or 0.93) times the
focal length, verified beside the (+30, -20) run (cost 693.6 px^2, 789.1 allowed): the fit test's
slack was one returned cost beyond the model's least, which certificates built at the image's
centre used (the (-60, +45) run's, registered there, costs 188 px^2 beyond it, 0.17 of what the
model costs beyond the returned cameras). The slack is now the noise's plus a quarter of that
misfit, at most the returned cost (calibration_tie._fit).
"""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.formulations.reconstruction import calibration_tie
from geocert.verify.checks import verify_any
from tests.support import stage as _stage
from tests.verify.test_calibration_tie import registered_at
from tests.verify.test_forgeries_review18 import SHIFTS, _reposed, _scene_job


@pytest.fixture(scope="module")
def off_centre() -> dict:
    """The defaults' run on the (+30, -20)-shifted scene, 200 tracks (verifying: review 18)."""
    return solve_job(_scene_job({}, points=200, shift=np.tile(SHIFTS["(+30, -20)"], (8, 1))))


def _central(result: dict, count: int, scale: float, every_track: bool) -> tuple[dict, dict]:
    """(the result naming ``count`` tracks nearest the scene's middle as the certificate's, the
    certificate's data): its cameras K [R | t], K the returned focal length times ``scale`` at the
    images' centre, adjusted (bundle model "fixed") to the held tracks' observations, or to every
    placed track's with ``every_track``; its points those of the held tracks."""
    from geocert.solvers.reconstruction import bundle

    cameras = {c["view"]: c for c in result["cameras"] if c.get("registered")}
    views = sorted(cameras)
    column = {v: k for k, v in enumerate(views)}
    placed = [p for p in result["points"] if p.get("point") is not None]
    X = np.array([p["point"] for p in placed])
    nearest = np.argsort(np.linalg.norm(X - np.median(X, axis=0), axis=1))[:count]
    held = sorted(placed[j]["track"] for j in nearest)
    fitted = placed if every_track else [p for p in placed if p["track"] in held]
    view, track, pixels = zip(*[(column[v], j, (u, w)) for j, p in enumerate(fitted) for v, u, w in p["observations"]])
    f = float(cameras[views[0]]["K"][0][0]) * scale
    K, R, t, Y, _, _ = bundle.metric(np.array([[f, 0.0, 319.5], [0.0, f, 239.5], [0.0, 0.0, 1.0]]),
                                     np.array([cameras[v]["R"] for v in views], dtype=float),
                                     np.array([cameras[v]["t"] for v in views], dtype=float),
                                     np.array([p["point"] for p in fitted]), np.array(view), np.array(track),
                                     np.array(pixels, dtype=float), model="fixed")
    row = {p["track"]: j for j, p in enumerate(fitted)}
    data = {**result["calibration_certificate"]["data"],
            "cameras": [(K @ np.c_[R[column[v]], t[column[v]]]).tolist() for v in views],
            "points": [[*Y[row[track]].tolist(), 1.0] for track in held]}
    forged = copy.deepcopy(result)
    stage = _stage(forged, "autocalibration")
    stage["certificate_views"], stage["certificate_tracks"] = views, held
    if "points_used" in stage:  # the record restated as the forger's certificate has it
        stage["points_used"] = len(held)
    return forged, data


@pytest.mark.parametrize("scale", [2.0, 0.7])
def test_a_certificate_of_a_few_middle_tracks_is_refused(off_centre, scale):
    """Found: 6 tracks at the scene's middle tied a certificate re-posed at twice (0.7 times) the
    focal length, and the whole document verified (certified_K 1599 px, determined; the tracks'
    800). Refused now: its cameras fit the other 194 placed points' 1,552 observations at 13,480
    px^2 (2.0) and 1,978 px^2 (0.7), the returned cameras at 218."""
    from tests.verify.test_calibration_tie import carrying

    result, data = _central(off_centre, 6, scale, every_track=False)
    forged = carrying(result, data)
    assert abs(forged["summary"]["calibration"]["certified_K"][0][0] / 800.0 - scale) < 0.02
    report = verify_any(json.loads(json.dumps(forged)))
    assert not report.valid
    assert "holds no point for" in report.first_failure["detail"], report.first_failure


@pytest.mark.parametrize("count, scale", [(6, 1.1), (6, 1.5), (20, 1.1)])
def test_middle_tracks_with_cameras_fitted_to_every_track_are_refused(off_centre, count, scale):
    """The forger's better certificate: its cameras adjusted to every placed track with K held,
    its points the middle tracks' only. Tied on main (6 tracks at 1.1 and 1.5 times, 20 at 1.1);
    refused now by the other tracks (at 1.1 times: 837 px^2 against 467 allowed), or already by the
    shared observations' fit since its allowance is the noise's (6 at 1.1: 13.1 px^2, 10.8 allowed;
    20 at 1.1: 39.7, 30.8)."""
    result, data = _central(off_centre, count, scale, every_track=True)
    with pytest.raises(calibration_tie.Invalid, match="holds no point for|fits the (48|160) observations"):
        result = registered_at(result, data)  # the record made to agree (review 23)
        calibration_tie.tie(result, _stage(result, "autocalibration"), data)


@pytest.fixture(scope="module")
def subset() -> dict:
    """The off-centre run with a calibration certificate of 40 of its 200 tracks (review 20)."""
    return solve_job(_scene_job({"autocalibration_points": 40}, points=200,
                                shift=np.tile(SHIFTS["(+30, -20)"], (8, 1))))


def test_a_genuine_certificate_of_a_subset_is_tied_by_the_other_tracks(subset):
    """The pipeline's certificate holds a spread of the tracks (here 40 of 200): its cameras fit
    the other 160 points' observations at 176 px^2, as the returned cameras do (203 allowed since
    review 24; its cameras are built at the estimated principal point, the model's ratio 1). The
    scope states it."""
    report = verify_any(json.loads(json.dumps(subset)))
    assert report.valid, report.first_failure
    tie = report.scope["calibration_tie"]
    assert tie["other_observations"] == 1280
    assert tie["other_cost_px2"] <= 0.9 * tie["other_allowed_cost_px2"]  # (review 24: the noise's allowance)


def test_a_certificate_holding_every_track_states_no_other(off_centre):
    tie = calibration_tie.tie(off_centre, _stage(off_centre, "autocalibration"),
                              off_centre["calibration_certificate"]["data"])
    assert tie["other_observations"] == 0


def test_the_triangulation_finds_the_points_least_cost():
    """_triangulated's cost is an evaluated one (at least each point's least): on exact images it
    finds them exactly, and on noisy ones no cost below scipy's least squares from the truth."""
    from scipy.optimize import least_squares

    rng = np.random.default_rng(3)
    K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
    P = []
    for a in np.linspace(-0.5, 0.5, 5):
        R = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
        P.append(K @ np.c_[R, -R @ [6 * np.sin(a), 0.0, -6 * np.cos(a)]])
    P = np.array(P)
    X = np.c_[rng.uniform(-1, 1, (30, 3)), np.ones(30)]
    view, group = np.tile(np.arange(5), 30), np.repeat(np.arange(30), 5)
    x = np.einsum("kij,kj->ki", P[view], X[group])
    exact = x[:, :2] / x[:, 2:]
    assert np.sum(calibration_tie._triangulated(P[view], group, exact)) < 1e-12
    noisy = exact + rng.normal(0, 1.0, exact.shape)
    found = calibration_tie._triangulated(P[view], group, noisy)
    for j in range(30):
        def residuals(y, j=j):
            q = P @ np.r_[y, 1.0]
            return (q[:, :2] / q[:, 2:] - noisy[group == j]).ravel()
        least = float(np.sum(least_squares(residuals, X[j, :3]).fun ** 2))
        assert least - 1e-6 <= float(np.sum(found[group == j])) <= least * (1 + 1e-6) + 1e-9, j


@pytest.mark.parametrize("scale, where", [(1.07, "centre"), (1.05, "returned"), (0.95, "returned")],
                         ids=["1.07x at the centre", "1.05x at the returned principal point",
                              "0.95x at the returned principal point"])
def test_a_certificate_of_every_track_reposed_is_refused(off_centre, scale, where):
    """Found: a certificate of every track re-posed at 1.07 times the focal length at the images'
    centre cost 693.6 px^2 on the 1,600 shared observations, the centred model 529.9 and the
    returned cameras 227.3, and verified (789.1 allowed: one whole returned cost of slack beyond the
    model's least). Re-posed at the returned principal point (held to the one-K reference, the
    returned cameras' 227.3) at 1.05 (0.95) times: 320.3 (340.3) px^2, 486.5 allowed. The slack is
    now the noise's (3 standard deviations, 17.0 px^2) plus a quarter of the model's misfit (75.7 at
    the centre, 0 at the principal point): 637.5 and 259.2 allowed."""
    K = np.array(next(c for c in off_centre["cameras"] if c.get("registered"))["K"], dtype=float)
    K[:2, :2] *= scale
    K[0, 1], K[1, 1] = 0.0, K[0, 0]
    if where == "centre":
        K[:2, 2] = [319.5, 239.5]
    with pytest.raises(calibration_tie.Invalid, match="fits the 1600 observations"):
        data = _reposed(off_centre, K)
        result = registered_at(off_centre, data)  # the record made to agree (review 23)
        calibration_tie.tie(result, _stage(result, "autocalibration"), data)


# --- tried, not passing: guards -----------------------------------------------------------------

def test_the_centred_fit_from_the_per_view_models_gauge_family_finds_the_least():
    """3 views, a principal point each and one view's own focal length: a 1-parameter family of
    frames images every observation as the returned one does (at a2 = 0.05 its focal lengths more
    than 1.2 times the scene's 800). The centred fit from it converges to the same least cost."""
    from scipy.optimize import least_squares

    from geocert.formulations.reconstruction import centred_fit
    from geocert.verify.reconstruction_members import intrinsics_of

    views = 3
    job = _scene_job({"principal_point": "per_view", "resect_cameras": False,
                      "autocalibration_on_critical_motion": "search"}, points=100,
                     shift=np.tile((30.0, -20.0), (8, 1)))
    keep = [{"views": [v for v in t["views"] if v < views],
             "points": [p for v, p in zip(t["views"], t["points"]) if v < views]} for t in job["data"]["tracks"]]
    job["data"]["tracks"] = [t for t in keep if len(t["views"]) >= 2]
    job["data"]["views"] = job["data"]["views"][:views]
    result = solve_job(job)
    cameras = [c for c in result["cameras"] if c.get("registered")]
    placed = [p for p in result["points"] if p.get("point") is not None]
    column = {c["view"]: k for k, c in enumerate(cameras)}
    view, point, uv = (np.array(a) for a in zip(*[(column[v], j, (u, w)) for j, p in enumerate(placed)
                                                  for v, u, w in p["observations"]]))
    uv = uv.astype(float)
    P = np.array([c["P"] for c in cameras], dtype=float)
    X = np.array([[*p["point"], 1.0] for p in placed])
    centres = np.tile([319.5, 239.5], (views, 1))

    def fitted(H):
        images = centred_fit.fit(np.array([Q @ H for Q in P]), centres, (np.linalg.inv(H) @ X.T).T, view, point, uv)
        return None if images is None else float(np.sum(np.square(images - uv)))

    def H_of(q, a2):
        S = np.array([[1.0, q[0], q[1]], [q[0], q[2], q[3]], [q[1], q[3], q[4]]])
        L = np.linalg.cholesky(S)
        return np.block([[L, np.zeros((3, 1))], [-(np.r_[q[5:7], a2] @ L)[None, :], np.ones((1, 1))]])

    def residuals(q, a2):
        out, focal = [], []
        for camera in P:
            M = (camera @ H_of(q, a2))[:, :3]
            w = M @ M.T
            w = w / w[2, 2]
            out += [(w[0, 1] - w[0, 2] * w[1, 2]) / 1e3, ((w[0, 0] - w[0, 2] ** 2) - (w[1, 1] - w[1, 2] ** 2)) / 1e5]
            focal.append(w[0, 0] - w[0, 2] ** 2)
        return np.array(out + [(focal[0] - focal[1]) / 1e5])

    genuine = fitted(np.eye(4))
    assert genuine is not None
    q = np.r_[0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0]
    for a2 in (0.01, 0.02, 0.03, 0.04, 0.05):  # continued from the returned frame
        q = least_squares(residuals, q, args=(a2,), xtol=1e-15, ftol=1e-15, gtol=1e-15).x
        H = H_of(q, a2)
        Ks = [intrinsics_of(Q @ H) for Q in P]
        assert max(abs(K[0, 1]) + abs(K[0, 0] - K[1, 1]) for K in Ks) < 1e-6 * Ks[0][0, 0]  # in the model
        assert fitted(H) == pytest.approx(genuine, rel=1e-6), a2
    assert Ks[0][0, 0] > 1.2 * 800.0  # the returned focal length far from the tracks' (a member, not the frame)


@pytest.fixture(scope="module")
def uncertified() -> dict:
    """The (+30, -20) run under L1L1, max_residual 20, max_nodes 1: every point node_limit (not
    certified), a calibration certificate beside them (verifying)."""
    return solve_job(_scene_job({"norm": "L1L1", "max_residual": 20.0, "max_nodes": 1}, points=200,
                                shift=np.tile(SHIFTS["(+30, -20)"], (8, 1))))


def _moved(result: dict, count: int) -> dict:
    """The result with its first ``count`` points (not certified: the result's to place) moved as
    far as max_residual lets them (each residual at most 18 px), their costs (and the certificate
    items' claims of them) and the summary's RMS made the moved points'."""
    forged = copy.deepcopy(result)
    P = {c["view"]: np.asarray(c["P"], dtype=float) for c in forged["cameras"] if c.get("registered")}

    def residuals(X, observations):
        x = np.array([P[v] @ np.r_[X, 1.0] for v, _, _ in observations])
        return x[:, :2] / x[:, 2:] - np.array([o[1:] for o in observations])

    rng = np.random.default_rng(0)
    for k, point in enumerate(forged["points"][:count]):
        assert point["certified"] is False
        X, observations = np.asarray(point["point"]), point["observations"]
        best = (0.0, X)
        for d in rng.normal(size=(100, 3)):
            d = d / np.linalg.norm(d)
            low, high = 0.0, 1.0
            for _ in range(40):
                low, high = ((low + high) / 2, high) if np.abs(residuals(X + (low + high) / 2 * d, observations)).max() \
                    <= 18.0 else (low, (low + high) / 2)
            cost = float(np.sum(residuals(X + low * d, observations) ** 2))
            best = max(best, (cost, X + low * d), key=lambda b: b[0])
        point["point"] = best[1].tolist()
        point["cost"] = float(np.abs(residuals(best[1], observations)).sum())
        item = forged["certificate"]["items"][k]
        item["point"], item["cost"] = point["point"], point["cost"]
    errors = np.concatenate([residuals(np.asarray(p["point"]), p["observations"]) for p in forged["points"]])
    forged["summary"]["rms_reprojection_px"] = float(np.sqrt(np.mean(np.sum(errors ** 2, axis=1))))
    return forged


def test_points_not_certified_placed_off_their_least_do_not_widen_the_tie(uncertified):
    """Found: the tie measured the returned cameras at the points as stated, and a point not
    certified is the result's to place. 10 of them moved within max_residual (the document still
    verifying) made the returned cameras' cost on the shared observations 28,736 px^2, and a
    certificate re-posed at 1.3 times the focal length (2,679 px^2) verified beside them
    (certified_K 1039.5 px). The returned cameras are now held to their own least on each track
    (227 px^2 here)."""
    from tests.verify.test_calibration_tie import carrying

    moved = _moved(uncertified, 10)
    assert verify_any(json.loads(json.dumps(moved))).valid  # moved, honestly stated: still a true document
    K = np.array(next(c for c in uncertified["cameras"] if c.get("registered"))["K"], dtype=float)
    K[:2, :2] *= 1.3
    K[:2, 2], K[0, 1] = [319.5, 239.5], 0.0
    forged = carrying(moved, _reposed(uncertified, K))
    report = verify_any(json.loads(json.dumps(forged)))
    assert not report.valid
    assert "calibration certificate" in report.first_failure["detail"], report.first_failure
    tie = calibration_tie.tie(moved, _stage(moved, "autocalibration"), uncertified["calibration_certificate"]["data"])
    assert tie["returned_cost_px2"] < 300.0
