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
