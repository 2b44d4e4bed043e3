"""Real photo sets with known cameras, as the benches and tests read them (numpy and OpenCV only:
no geocert import, so a test of any layer may use them).

Each set lives in its own folder under a data root (``--data`` of the benches, else the
``GEOCERT_BENCH_DATA`` environment variable, else bench-data beside the checkout); the photos are used as
published, never downscaled. None of them ships with geocert: :func:`load` raises
:class:`MissingSet` naming the folder and where the files come from, and a test that needs one
skips with that message (``pytest.skip(str(error))``). All but dinoSparseRing and the Corridor are
fetched, each file checked, by ``python -m bench.fetch_photo_sets`` (testing/fetch_photo_sets.py).

Sets, their owners (credit them when you use them) and what a test can do with each:

- ``dinoSparseRing``: Middlebury multi-view stereo "dinoSparseRing" (Seitz, Curless, Diebel,
  Scharstein and Szeliski, CVPR 2006): 14 of its 16 photos, 640x480 PNG, an untextured object on
  a turntable, ground-truth K, R, t per photo (``dinoSR_par.txt``); focal length 3310 px (a long
  lens). Folder ``middlebury_dinoSparseRing`` (the shared copy /work/shared/data/... is used when
  the data root has none). Tests: a sparse, wide-baseline ring with a long lens, K known or not.
- ``templeRing``: Middlebury "templeRing" (same authors): 47 photos, 640x480 PNG, a plaster
  temple on a turntable, ground-truth K, R, t (``templeR_par.txt``); focal length 1520 px.
  Folder ``middlebury_templeRing``. Tests: a dense ring (every image in file order, shuffled, or
  every 2nd), registration in any file order.
- ``templeSparseRing``: Middlebury "templeSparseRing": 16 photos of the same temple, ground truth
  as above. Folder ``middlebury_templeSparseRing``. Tests: a sparse ring with a textured object.
- ``corridor``: Oxford VGG "Corridor" (Basement) sequence: 11 frames 512x512 PGM moving forward
  along a corridor, VGG's 3x4 cameras per frame (``bt.###.P``) and their corner matches
  (``bt.nview-corners``); credit the Visual Geometry Group, University of Oxford. VGG's cameras
  share no exact K (focal 495-518 px, principal point x 272-359 px, skew up to 17 px), so the
  set's K is their median with zero skew and every figure against it is approximate. Folder
  ``oxford_corridor``. Tests: forward motion, from the photos or from VGG's matches
  (:func:`corridor_tracks`).
- ``kittiStraight`` and ``kittiTurn``: two 51-frame excerpts of the KITTI odometry benchmark
  (Geiger, Lenz and Urtasun, "Are we ready for autonomous driving? The KITTI vision benchmark
  suite", CVPR 2012; licence CC BY-NC-SA 3.0, non-commercial: the data are read, never shipped),
  the left grey camera (rectified: no distortion) of a car driving down a road, and the
  ground-truth poses; K from the benchmark's ``calib.txt`` (P0). ``kittiStraight``: 1226x370 PNG,
  f 707.09 px (the calibration of sequences 04-12), 60 m straight ahead (1.2 m a frame, 1.3
  degrees of rotation in all); ``kittiTurn``: 1241x376 PNG, f 718.86 px (sequences 00-02), 44 m
  through a right turn of 98 degrees. The sets are every 2nd frame (26 photos, 1.9 to 2.5 m
  apart). Folders ``kitti_sequence_1`` and ``kitti_sequence_2`` (``image_l/######.png``,
  ``calib.txt``, ``poses.txt``), as a public copy on GitHub holds them (niconielsen32/VisualSLAM,
  KITTI_sequence_1 and KITTI_sequence_2).
  Tests: forward motion along the optical axis, the epipole inside the image.
- ``sceaux``: "Sceaux Castle", 11 JPEGs 2832x2128 (6 Mpx) from a Kodak Z612 with EXIF focal
  length, photographs copyright 2012 Pierre Moulon, published as openMVG's sample data set; K
  (``K.txt``, openMVG's) but no ground-truth poses. Folder ``sceaux_castle``. Tests: high
  resolution JPEGs, focal length against K.txt, EXIF as a prior.

File formats: Middlebury ``*_par.txt``: a count line, then per photo ``name k11..k33 r11..r33 t1 t2
t3`` with x = K [R | t] X in pixels, origin top-left. VGG ``bt.###.P``: one 3x4 matrix per frame,
pixels; ``bt.###.corners``: x y per line; ``bt.nview-corners``: per 3D point, one corner index per
frame or ``*``. openMVG ``K.txt``: the 3x3 K. KITTI ``calib.txt``: per line ``P#: p11..p34``, camera # (0: left grey)
in pixels; ``poses.txt``: per frame 12 numbers, the 3x4 [R | c] taking camera 0's frame to the
first frame's (camera to world, not world to camera).
"""

from __future__ import annotations

import os
import random
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

# Where the fetched photo sets are (GEOCERT_BENCH_DATA or --data overrides), and the shared data
# set beside the checkout (GEOCERT_SHARED_DATA overrides), as the tests find it.
DEFAULT_ROOT = Path(__file__).resolve().parents[2] / "bench-data"
SHARED = Path(os.environ.get("GEOCERT_SHARED_DATA") or Path(__file__).resolve().parents[2] / "shared" / "data")
MIDDLEBURY = "https://vision.middlebury.edu/mview/data/ (Seitz et al., CVPR 2006)"
VGG = "https://www.robots.ox.ac.uk/~vgg/data/data-mview.html (Visual Geometry Group, University of Oxford)"
KITTI = ("https://github.com/niconielsen32/VisualSLAM (folders KITTI_sequence_1 and KITTI_sequence_2: image_l, "
         "calib.txt, poses.txt), from https://www.cvlibs.net/datasets/kitti/eval_odometry.php (CC BY-NC-SA 3.0)")


@dataclass(frozen=True)
class Camera:
    """x = K [R | t] X in pixels; R a rotation (det +1), K with a positive diagonal."""

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray

    @property
    def center(self) -> np.ndarray:
        return -self.R.T @ self.t


@dataclass
class PhotoSet:
    key: str
    title: str
    credit: str
    directory: Path
    names: list[str]  # the photos in file order
    K: np.ndarray  # the one K a "K known" run is given
    truth: dict[str, Camera] = field(default_factory=dict)  # per photo; empty: no ground-truth poses
    dense_ring: bool = False  # an "every 2nd photo" order is meaningful
    truth_note: str = ""

    def path(self, name: str) -> Path:
        return self.directory / name

    def order(self, order: str, seed: int = 0) -> list[str]:
        """The photos in an order: "file" (as published), "shuffled" (random.Random(seed)), "every2"
        (every 2nd photo, in file order)."""
        if order == "file":
            return list(self.names)
        if order == "shuffled":
            names = list(self.names)
            random.Random(seed).shuffle(names)
            return names
        if order == "every2":
            return list(self.names[::2])
        raise ValueError(f"unknown order {order!r} (file, shuffled, every2)")


class MissingSet(FileNotFoundError):
    def __init__(self, key: str, path: Path, source: str):
        from testing.fetch_photo_sets import SETS as FETCHABLE

        fetch = f", or `python -m bench.fetch_photo_sets --sets {key}`" if key in FETCHABLE else ""
        super().__init__(f"photo set {key!r} not found at {path}: get it from {source}{fetch} "
                         "(see testing/photo_sets.py)")
        self.key, self.path, self.source = key, path, source


def data_root(root: str | os.PathLike | None = None) -> Path:
    return Path(root or os.environ.get("GEOCERT_BENCH_DATA") or DEFAULT_ROOT)


def read_middlebury_par(path: Path) -> dict[str, Camera]:
    """A Middlebury ``*_par.txt``: per photo name, its K, R, t."""
    cameras = {}
    for line in path.read_text().splitlines()[1:]:
        fields = line.split()
        if len(fields) != 22:
            continue
        v = np.array(fields[1:], dtype=float)
        cameras[fields[0]] = Camera(v[:9].reshape(3, 3), v[9:18].reshape(3, 3), v[18:21])
    return cameras


def camera_from_P(P: np.ndarray) -> Camera:
    """K, R, t of a 3x4 camera by RQ decomposition, signs fixed so that K's diagonal is positive
    and det R = +1 (P scaled by -1 when needed: the same camera)."""
    from scipy.linalg import rq

    P = np.asarray(P, dtype=float)
    if np.linalg.det(P[:, :3]) < 0:
        P = -P
    K, R = rq(P[:, :3])
    signs = np.diag(np.sign(np.diag(K)))
    K, R = K @ signs, signs @ R
    t = np.linalg.solve(K, P[:, 3])
    return Camera(K / K[2, 2], R, t)


def _middlebury(key, folder, prefix, title, root: Path, dense_ring=False) -> PhotoSet:
    directory = root / folder
    if not (directory / f"{prefix}_par.txt").exists() and (SHARED / folder / f"{prefix}_par.txt").exists():
        directory = SHARED / folder
    par = directory / f"{prefix}_par.txt"
    if not par.exists():
        raise MissingSet(key, root / folder, MIDDLEBURY)
    truth = read_middlebury_par(par)
    names = sorted(n for n in truth if (directory / n).exists())
    if len(names) < 2:
        raise MissingSet(key, directory, MIDDLEBURY)
    return PhotoSet(key, title, "Middlebury multi-view stereo data (Seitz, Curless, Diebel, Scharstein, Szeliski, "
                    "CVPR 2006)", directory, names, truth[names[0]].K, {n: truth[n] for n in names}, dense_ring)


def _corridor(root: Path) -> PhotoSet:
    directory = root / "oxford_corridor"
    names = [f"bt.{i:03d}.pgm" for i in range(11)]
    if not all((directory / n).exists() and (directory / n.replace(".pgm", ".P")).exists() for n in names):
        raise MissingSet("corridor", directory, VGG)
    truth = {n: camera_from_P(np.loadtxt(directory / n.replace(".pgm", ".P"))) for n in names}
    Ks = np.array([c.K for c in truth.values()])
    K = np.median(Ks, axis=0)
    K[0, 1] = 0.0
    return PhotoSet("corridor", "Oxford Corridor, 11 frames 512x512 (forward motion)", "Oxford VGG", directory, names,
                    K, truth, truth_note="VGG's cameras share no exact K: the median K, zero skew")


def _sceaux(root: Path) -> PhotoSet:
    directory = root / "sceaux_castle"
    names = sorted(p.name for p in directory.glob("*.JPG")) if directory.exists() else []
    if len(names) < 2 or not (directory / "K.txt").exists():
        raise MissingSet("sceaux", directory, "https://github.com/openMVG/ImageDataset_SceauxCastle")
    return PhotoSet("sceaux", "Sceaux Castle, 11 JPEGs 2832x2128 (EXIF focal length)",
                    "photographs (c) 2012 Pierre Moulon, openMVG sample data", directory, names,
                    np.loadtxt(directory / "K.txt"), truth_note="K from openMVG's K.txt; no ground-truth poses")


def _kitti(key: str, folder: str, title: str, root: Path) -> PhotoSet:
    """Every 2nd frame of a KITTI excerpt: camera 0's images, K from calib.txt's P0 and the
    ground-truth poses (camera to world) turned into x = K [R | t] X."""
    directory = root / folder
    images = sorted((directory / "image_l").glob("*.png")) if directory.exists() else []
    if len(images) < 2 or not (directory / "calib.txt").exists() or not (directory / "poses.txt").exists():
        raise MissingSet(key, directory, KITTI)
    P0 = np.array(next(line for line in (directory / "calib.txt").read_text().splitlines() if line.strip())
                  .split()[-12:], dtype=float).reshape(3, 4)
    K = P0[:, :3] / P0[2, 2]
    poses = np.loadtxt(directory / "poses.txt").reshape(-1, 3, 4)
    names, truth = [], {}
    for index, path in enumerate(images[: len(poses)]):
        if index % 2:
            continue
        name = path.name
        R_wc, centre = poses[index][:, :3], poses[index][:, 3]
        names.append(name)
        truth[name] = Camera(K, R_wc.T, -R_wc.T @ centre)
    return PhotoSet(key, title, "KITTI odometry benchmark (Geiger, Lenz, Urtasun, CVPR 2012), CC BY-NC-SA 3.0",
                    directory / "image_l", names, K, truth)


SETS = {
    "dinoSparseRing": lambda root: _middlebury("dinoSparseRing", "middlebury_dinoSparseRing", "dinoSR",
                                               "Middlebury dinoSparseRing, 14 photos 640x480", root),
    "templeRing": lambda root: _middlebury("templeRing", "middlebury_templeRing", "templeR",
                                           "Middlebury templeRing, 47 photos 640x480 (dense ring)", root, True),
    "templeSparseRing": lambda root: _middlebury("templeSparseRing", "middlebury_templeSparseRing", "templeSR",
                                                 "Middlebury templeSparseRing, 16 photos 640x480", root),
    "corridor": _corridor,
    "sceaux": _sceaux,
    "kittiStraight": lambda root: _kitti("kittiStraight", "kitti_sequence_1",
                                         "KITTI, 26 frames 1226x370 down a straight road (forward motion)", root),
    "kittiTurn": lambda root: _kitti("kittiTurn", "kitti_sequence_2",
                                     "KITTI, 26 frames 1241x376 through a right turn (forward motion)", root),
}


def load(key: str, root: str | os.PathLike | None = None) -> PhotoSet:
    """The set ``key`` (see SETS) under the data root; MissingSet when its files are not there."""
    return SETS[key](data_root(root))


def corridor_tracks(photo_set: PhotoSet) -> list[tuple[np.ndarray, np.ndarray]]:
    """VGG's corner matches of the Corridor as tracks: (view indices, pixels) per 3D point seen in
    at least 2 frames, views in the set's file order."""
    directory = photo_set.directory
    corners = [np.loadtxt(directory / n.replace(".pgm", ".corners")) for n in photo_set.names]
    tracks = []
    for row in np.loadtxt(directory / "bt.nview-corners", dtype=str):
        views = [v for v, index in enumerate(row) if index != "*"]
        if len(views) >= 2:
            tracks.append((np.array(views), np.array([corners[v][int(row[v])] for v in views])))
    return tracks
