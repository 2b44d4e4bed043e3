"""Writes the example jobs in this directory: one runnable job document per kind (and per method
where a kind has two), each solved in seconds. With ``--shared DIR`` it also writes jobs from the
real datasets in DIR (Oxford VGG's Dinosaur and Model House, Middlebury's dinoSparseRing) into
``examples/real/``; those are not committed (the datasets carry no licence that allows copying
them here), so they are made from the datasets where you have them.

    .venv/bin/python examples/generate.py                      # the synthetic examples
    .venv/bin/python examples/generate.py --shared ../shared/data   # and the real-data ones

Every synthetic example comes from one of geocert's scene generators with a fixed seed, so its
ground truth is known: ``build(name)`` returns the job and that truth, which the tests
(tests/service/test_examples.py) check the service's answers against."""

from __future__ import annotations

import argparse
import base64
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DIGITS = 6  # decimals kept in pixels and coordinates: far below the noise, and stable across machines


def rounded(values, digits: int = DIGITS):
    return np.round(np.asarray(values, dtype=float), digits).tolist()


def look_at(centre, target, focal=800.0, size=(640, 480)):
    """K [R | -R c] at ``centre`` looking at ``target``."""
    z = np.asarray(target, float) - centre
    z /= np.linalg.norm(z)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    K = np.array([[focal, 0, size[0] / 2], [0, focal, size[1] / 2], [0, 0, 1.0]])
    return K @ np.hstack([R, -R @ np.asarray(centre, float)[:, None]])


def project(P, X):
    x = np.c_[X, np.ones(len(X))] @ np.asarray(P).T
    return x[:, :-1] / x[:, -1:]


# --- one builder per example: (job, truth) ---------------------------------------------------------

def triangulation():
    """40 points seen by 2 to 8 of 8 cameras (800 px, 640x480) round a unit cloud, 1 px noise."""
    rng = np.random.default_rng(101)
    cameras = [look_at(rng.normal(size=3) * 2 + [0, 0, -8.0], rng.normal(size=3) * 0.3) for _ in range(8)]
    points, tracks = rng.normal(size=(40, 3)), []
    for X in points:
        views = sorted(rng.choice(8, size=int(rng.integers(2, 9)), replace=False).tolist())
        pixels = np.array([project(cameras[v], X[None])[0] for v in views]) + rng.normal(size=(len(views), 2))
        tracks.append({"views": views, "points": rounded(pixels)})
    job = {"kind": "triangulation", "data": {"cameras": rounded(cameras, 9), "tracks": tracks},
           "options": {"norm": "L2L2", "certificate": "full"}}
    return job, {"points": points.tolist()}


def resection():
    """Two cameras, each from 30 points (3D to pixels), 0.5 px noise."""
    rng = np.random.default_rng(102)
    maps, truth = [], []
    for _ in range(2):
        P = look_at(rng.normal(size=3) * 2 + [0, 0, -8.0], rng.normal(size=3) * 0.3)
        source = rng.normal(size=(30, 3))
        target = project(P, source) + rng.normal(size=(30, 2)) * 0.5
        maps.append({"source": rounded(source), "target": rounded(target)})
        truth.append((P / np.linalg.norm(P)).tolist())
    return ({"kind": "resection", "data": {"maps": maps}, "options": {"norm": "L2L2", "certificate": "full"}},
            {"matrices": truth})


def homography_plane():
    """A homography of P^2: a plane (z = 0) seen by two cameras, 20 points each, 0.5 px noise."""
    rng = np.random.default_rng(103)
    maps, truth = [], []
    for _ in range(2):
        P = look_at(rng.normal(size=3) * 2 + [0, 0, -8.0], rng.normal(size=3) * 0.3)
        H = P[:, [0, 1, 3]]
        source = rng.uniform(-2, 2, size=(20, 2))
        target = project(H, source) + rng.normal(size=(20, 2)) * 0.5
        maps.append({"source": rounded(source), "target": rounded(target)})
        truth.append((H / np.linalg.norm(H)).tolist())
    return ({"kind": "homography", "data": {"maps": maps}, "options": {"norm": "L2L1", "certificate": "full"}},
            {"matrices": truth})


def homography_space():
    """A homography of P^3 (3D to 3D, e.g. two projective reconstructions of one scene): 25 points,
    noise 0.01 (the cloud's spread is 1)."""
    rng = np.random.default_rng(104)
    H = np.eye(4) + rng.normal(size=(4, 4)) * 0.05
    H[3] = [0.02, -0.01, 0.03, 1.0]
    source = rng.normal(size=(25, 3))
    target = project(H, source) + rng.normal(size=(25, 3)) * 0.01
    job = {"kind": "homography", "data": {"maps": [{"source": rounded(source), "target": rounded(target)}]},
           "options": {"norm": "L2L2", "certificate": "full"}}
    return job, {"matrices": [(H / np.linalg.norm(H)).tolist()]}


def _autocalibration_scene(motion: str):
    from geocert.solvers.autocalibration import scenes

    return scenes.make_scene(8, 0.1, points=40, seed=5, motion=motion)


def autocalibration_stratified():
    """Stratified autocalibration of a projective reconstruction: 8 views all round, 40 points,
    0.1% noise, moved by a random projective frame; K is 1000 px, principal point (500, 500)."""
    scene = _autocalibration_scene("sphere")
    data = {"cameras": rounded(scene.cameras, 9), "points": rounded(scene.points, 9),
            "image_size": list(scene.image_size)}
    return ({"kind": "autocalibration", "data": data, "options": {"method": "stratified", "certificate": "full"}},
            {"K": scene.K.tolist()})


def autocalibration_direct():
    """The same reconstruction by the direct method (the absolute dual quadric, thesis chapter 7)."""
    job, truth = autocalibration_stratified()
    job["options"] = {"method": "direct", "chirality": "centers", "certificate": "full"}
    return job, truth


def autocalibration_turntable():
    """What it exercises: the critical motion warning ``orbital_motion``. A turntable (every
    rotation about one axis) is a critical motion, so the data do not fix constant intrinsics
    (Sturm 1997): the modulus cost is flat along the planes the motion leaves open, so the search
    stops at its node limit, and K is one of many that fit as well. The result says so
    (``determinacy.warnings``: orbital_motion, ``determined``: false). A node limit, not a time
    limit, ends it: the same place on any machine."""
    scene = _autocalibration_scene("ring")
    data = {"cameras": rounded(scene.cameras, 9), "points": rounded(scene.points, 9),
            "image_size": list(scene.image_size)}
    wide = {"focal": [300, 5000], "aspect": [0.5, 2], "skew": [-100, 100], "principal_point": [[0, 1000], [0, 1000]]}
    return ({"kind": "autocalibration", "data": data, "options": {"intrinsics": wide, "max_nodes": 300}},
            {"K": scene.K.tolist()})


def bilinear():
    """Shape from exemplars: 3 basis shapes of 12 points; 4 frames, each an affine camera's image
    of a convex combination of them, 0.5 px noise, one point unseen in frame 2."""
    rng = np.random.default_rng(105)
    basis = rng.uniform(-1, 1, size=(3, 12, 3))
    frames, truth = [], []
    for index in range(4):
        alpha = rng.dirichlet(np.ones(3))
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        M = 100 * q[:2]
        t = rng.uniform(-50, 50, size=2)
        shape = np.tensordot(alpha, basis, axes=1)
        points = shape @ M.T + t + rng.normal(size=(12, 2)) * 0.5
        listed = rounded(points, 4)
        if index == 2:
            listed[5] = None
        frames.append({"points": listed})
        truth.append({"coefficients": alpha.tolist(), "camera": np.c_[M, t].tolist()})
    job = {"kind": "bilinear", "data": {"basis": rounded(basis), "frames": frames},
           "options": {"norm": "L2L2", "coefficients": "convex", "certificate": "full"}}
    return job, {"frames": truth}


def stereo_lines_pair():
    """One frame pair of a calibrated stereo rig (the thesis's: 320 px, 7.4 cm baseline) seeing 20
    lines, as segments in each of the four images (unmatched, in no particular order), 0.3 px
    noise: what a robot sends each time it moves (docs/api.md: Prefer: wait)."""
    from geocert.solvers.lines.scenes import pair_scene

    rng = np.random.default_rng(106)
    scene = pair_scene(rng, 20, noise_px=0.3, degrees=3.0, metres=0.08)
    rig = scene.rig
    images = [scene.segments[:, k] for k in range(4)]
    images = [segments[rng.permutation(len(segments))] for segments in images]
    frames = [{"left": rounded(images[0], 3), "right": rounded(images[1], 3)},
              {"left": rounded(images[2], 3), "right": rounded(images[3], 3)}]
    job = {"kind": "stereo_lines",
           "data": {"rig": {"K_left": rig.K_left.tolist(), "K_right": rig.K_right.tolist(), "R": rig.R.tolist(),
                            "t": rig.t.tolist()}, "frames": frames},
           "options": {"solver": "incremental"}}
    return job, {"R": scene.R.tolist(), "t": scene.t.tolist()}


def reconstruction_tracks():
    """From matches alone (no cameras) to a metric reconstruction: 8 views (800 px, 640x480) of
    60 points, each seen by about 80% of the views, 0.5 px noise."""
    from geocert.solvers.reconstruction import synthetic

    scene = synthetic.scene(views=8, points=60, noise_px=0.5, seed=7, visibility=0.8)
    data = {"views": [{"name": f"view{v}.png", "image_size": list(scene.image_size)} for v in range(8)],
            "tracks": [{"views": [int(v) for v in views], "points": rounded(pixels)} for views, pixels in scene.tracks]}
    return ({"kind": "reconstruction", "data": data, "options": {}},
            {"K": scene.K.tolist(), "rotations": scene.rotations.tolist()})


def reconstruction_photos():
    """From photos: 6 rendered views (320x240 JPEG) of a textured box on a textured ground, over
    a 75 degree arc; the calibration (f = 350 px) is given, so matching, the calibrated
    reconstruction and the certified points and cameras run, no autocalibration."""
    import cv2

    from geocert.solvers.reconstruction import render

    scene = render.box_scene(n_views=6, image_size=(320, 240), focal=350.0, arc_deg=75, seed=3)
    images = []
    for k, camera in enumerate(scene.cameras):
        ok, jpeg = cv2.imencode(".jpg", scene.render(camera), [cv2.IMWRITE_JPEG_QUALITY, 85])
        assert ok
        images.append({"name": f"box{k}.jpg", "content": base64.b64encode(jpeg.tobytes()).decode()})
    K = scene.cameras[0].K
    return ({"kind": "reconstruction", "data": {"images": images}, "options": {"intrinsics": {"K": K.tolist()}}},
            {"K": K.tolist(), "rotations": [c.R.tolist() for c in scene.cameras]})


EXAMPLES = {
    "triangulation": triangulation,
    "resection": resection,
    "homography-plane": homography_plane,
    "homography-space": homography_space,
    "autocalibration-stratified": autocalibration_stratified,
    "autocalibration-direct": autocalibration_direct,
    "autocalibration-turntable": autocalibration_turntable,
    "bilinear": bilinear,
    "stereo-lines-pair": stereo_lines_pair,
    "reconstruction-tracks": reconstruction_tracks,
    "reconstruction-photos": reconstruction_photos,
}


def build(name: str) -> tuple[dict, dict]:
    """The example's job document and its ground truth."""
    return EXAMPLES[name]()


def path(name: str) -> Path:
    return HERE / f"{name}.json"


# --- real data (not committed) ------------------------------------------------------------------

def dinosaur_reconstruction(shared: Path) -> dict:
    """The Oxford Dinosaur from its 4983 tracks alone (36 views, 720x576): about 4 minutes."""
    from geocert.solvers.datasets import load_dinosaur

    _, tracks = load_dinosaur(shared / "oxford_dinosaur")
    return {"kind": "reconstruction",
            "data": {"views": [{"name": f"viff.{v:03d}", "image_size": [720, 576]} for v in range(36)],
                     "tracks": [{"views": t.views, "points": t.points.tolist()} for t in tracks]},
            "options": {}}


def dinosaur_autocalibration(shared: Path) -> dict:
    """The Dinosaur's 36 projective cameras (VGG's) and its points seen in 6 views or more, with
    wide intrinsics ranges: both stages certify, and K is not determined (a turntable)."""
    from geocert.solvers.datasets import load_dinosaur
    from geocert.solvers.reconstruction.linear import triangulate

    cameras, tracks = load_dinosaur(shared / "oxford_dinosaur")
    points = [triangulate(cameras[track.views], track.points) for track in tracks if len(track.views) >= 6]
    wide = {"focal": [100, 5000], "aspect": [0.2, 5], "skew": [-200, 200], "principal_point": [[0, 720], [0, 576]]}
    return {"kind": "autocalibration",
            "data": {"cameras": cameras.tolist(), "points": np.array(points).tolist(), "image_size": [720, 576]},
            "options": {"intrinsics": wide}}


def house_triangulation(shared: Path) -> dict:
    """The Oxford Model House's 672 tracks triangulated in VGG's 10 cameras (768x576)."""
    from geocert.solvers.datasets import load_house

    cameras, points, views = load_house(shared / "oxford_house")
    seen: dict[int, list] = {}
    for v, view in enumerate(views):
        for index, pixel in zip(view.point_indices, view.pixels):
            seen.setdefault(int(index), []).append((v, pixel.tolist()))
    tracks = [{"views": [v for v, _ in obs], "points": [p for _, p in obs]}
              for _, obs in sorted(seen.items()) if len(obs) >= 2]
    return {"kind": "triangulation", "data": {"cameras": cameras.tolist(), "tracks": tracks},
            "options": {"norm": "L2L2", "certificate": "full"}}


def ring_photos(shared: Path) -> dict:
    """Middlebury's dinoSparseRing (Seitz, Curless, Diebel, Scharstein and Szeliski, CVPR 2006): 14
    photos (640x480) with their calibration, K known: about a minute."""
    directory = shared / "middlebury_dinoSparseRing"
    rows = [line.split() for line in (directory / "dinoSR_par.txt").read_text().splitlines()[1:] if line.strip()]
    images = [{"name": row[0], "content": base64.b64encode((directory / row[0]).read_bytes()).decode()} for row in rows]
    K = np.array(rows[0][1:10], dtype=float).reshape(3, 3)
    ring = {"intrinsics": {"K": K.tolist()}, "min_inliers": 10, "merge_components": True,
            "features": {"max_features": 0, "contrast_threshold": 0.005, "ratio": 0.85, "ransac_threshold_px": 2,
                         "guided_ratio": 0.8}}  # the ring options of docs/benchmarks.md
    return {"kind": "reconstruction", "data": {"images": images}, "options": ring}


REAL = {
    "house-triangulation": house_triangulation,
    "dinosaur-autocalibration": dinosaur_autocalibration,
    "dinosaur-reconstruction": dinosaur_reconstruction,
    "ring-photos": ring_photos,
}


def write(document: dict, target: Path) -> None:
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(json.dumps(document, separators=(",", ":")) + "\n")
    print(f"{target} ({target.stat().st_size / 1024:.0f} kB)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--shared", type=Path, help="the real datasets' directory (e.g. ../shared/data)")
    parser.add_argument("names", nargs="*", help="only these examples (default: all)")
    args = parser.parse_args(argv)
    for name in args.names or EXAMPLES:
        if name in EXAMPLES:
            write(build(name)[0], path(name))
    if args.shared is not None:
        for name, make in REAL.items():
            if not args.names or name in args.names:
                write(make(args.shared), HERE / "real" / f"{name}.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
