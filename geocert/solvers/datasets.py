"""Readers for the real datasets in ``shared/data`` and ``bench-data`` (Oxford VGG multi-view data;
credit: Oxford Visual Geometry Group, A. Fitzgibbon and A. Zisserman; the Middlebury multi-view
stereo sets: Seitz, Curless, Diebel, Scharstein and Szeliski, CVPR 2006). Used by tests and
benchmarks."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass
class Track:
    views: list[int]
    points: np.ndarray  # (k, 2) pixels


def load_dinosaur(directory: str | Path) -> tuple[np.ndarray, list[Track]]:
    """The Dinosaur turntable: 36 projective cameras and 4983 tracks (x = column, y = row)."""
    directory = Path(directory)
    rows = np.loadtxt(directory / "dino_Ps.txt", comments="#")
    cameras = rows.reshape(36, 3, 4)
    table = np.loadtxt(directory / "viff.xy").reshape(-1, 36, 2)
    tracks = []
    for row in table:
        seen = np.flatnonzero(np.all(row != -1.0, axis=1))
        tracks.append(Track(seen.tolist(), row[seen]))
    return cameras, tracks


@dataclass
class ViewCorrespondences:
    point_indices: np.ndarray  # indices into the 3D points
    pixels: np.ndarray  # (k, 2)


def load_house(directory: str | Path) -> tuple[np.ndarray, np.ndarray, list[ViewCorrespondences]]:
    """The Model House: 10 cameras, 672 3D points, and each view's 3D-2D correspondences."""
    directory = Path(directory)
    cameras = np.array([np.loadtxt(directory / "3D" / f"house.{i:03d}.P") for i in range(10)])
    points = np.loadtxt(directory / "3D" / "house.p3d")
    matches = np.loadtxt(directory / "2D" / "house.nview-corners", dtype=int)
    views = []
    for i in range(10):
        corners = np.loadtxt(directory / "2D" / f"house.{i:03d}.corners")
        seen = np.flatnonzero(matches[:, i] >= 0)
        views.append(ViewCorrespondences(seen, corners[matches[seen, i]]))
    return cameras, points, views


@dataclass
class CalibratedViews:
    """Ground-truth cameras P_i = K_i [R_i | t_i] (pixels) and what they look at."""

    names: list[str]
    K: np.ndarray  # (m, 3, 3)
    R: np.ndarray  # (m, 3, 3)
    t: np.ndarray  # (m, 3)
    box: tuple[np.ndarray, np.ndarray] | None  # the object's bounding box (world), when the set states it
    image_size: tuple[int, int]

    @property
    def cameras(self) -> np.ndarray:
        return np.einsum("iab,ibc->iac", self.K, np.concatenate([self.R, self.t[:, :, None]], axis=2))

    @property
    def centres(self) -> np.ndarray:
        return -np.einsum("iba,ib->ia", self.R, self.t)

    def subset(self, views) -> "CalibratedViews":
        views = list(views)
        return CalibratedViews([self.names[i] for i in views], self.K[views], self.R[views], self.t[views], self.box,
                               self.image_size)


def load_middlebury(directory: str | Path) -> CalibratedViews:
    """A Middlebury multi-view set's ``*_par.txt`` ("name k11..k33 r11..r33 t1 t2 t3" a view, after
    a count line; P = K [R | t]) and the bounding box its README states."""
    directory = Path(directory)
    par = next(directory.glob("*_par.txt"))
    rows = [line.split() for line in par.read_text().splitlines()[1:] if len(line.split()) == 22]
    numbers = np.array([[float(v) for v in row[1:]] for row in rows])
    box = None
    readme = directory / "README.txt"
    if readme.exists():
        corners = re.findall(r"\(([-\d.]+) ([-\d.]+) ([-\d.]+)\)", readme.read_text())
        if len(corners) >= 2:
            box = (np.array(corners[0], dtype=float), np.array(corners[1], dtype=float))
    return CalibratedViews([row[0] for row in rows], numbers[:, :9].reshape(-1, 3, 3),
                           numbers[:, 9:18].reshape(-1, 3, 3), numbers[:, 18:21], box, (640, 480))


def load_vgg_cameras(directory: str | Path, stem: str, image_size: tuple[int, int]) -> CalibratedViews:
    """VGG's ``<stem>.###.P`` cameras (e.g. the Corridor's ``bt``, the Model House's ``house``),
    each split as K [R | t] (K[2, 2] = 1, a positive diagonal; the points in ``<stem>.p3d``
    bound the box)."""
    from scipy.linalg import rq

    directory = Path(directory)
    files = sorted(directory.glob(f"{stem}.[0-9][0-9][0-9].P"))
    if not files:
        files = sorted((directory / "3D").glob(f"{stem}.[0-9][0-9][0-9].P"))
    Ks, Rs, ts = [], [], []
    for path in files:
        P = np.loadtxt(path)
        P = P * np.sign(np.linalg.det(P[:, :3]))
        K, R = rq(P[:, :3])
        D = np.diag(np.sign(np.diag(K)))
        K, R = K @ D, D @ R
        Ks.append(K / K[2, 2])
        Rs.append(R)
        ts.append(np.linalg.solve(K, P[:, 3]))
    points_file = next((p for p in (directory / f"{stem}.p3d", directory / "3D" / f"{stem}.p3d") if p.exists()), None)
    box = None
    if points_file is not None:
        X = np.loadtxt(points_file)
        box = (X.min(axis=0), X.max(axis=0))
    return CalibratedViews([p.stem for p in files], np.array(Ks), np.array(Rs), np.array(ts), box, image_size)
