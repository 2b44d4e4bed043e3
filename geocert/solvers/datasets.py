"""Readers for the real datasets in ``shared/data`` (Oxford VGG multi-view data; credit: Oxford
Visual Geometry Group, A. Fitzgibbon and A. Zisserman). Used by tests and benchmarks."""

from __future__ import annotations

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
