"""The observations a reconstruction is built from: tracks (one 3D point seen in several views),
held as flat arrays for the bundle adjustments, with each observation's inlier flag."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Observations:
    """Every observation of every track, flat: track index, view index, pixel (u, v)."""

    track: np.ndarray  # (M,) int
    view: np.ndarray  # (M,) int
    pixel: np.ndarray  # (M, 2) float
    n_tracks: int
    n_views: int

    @classmethod
    def from_tracks(cls, tracks: list[tuple[np.ndarray, np.ndarray]], n_views: int) -> "Observations":
        track = np.concatenate([np.full(len(v), i, dtype=int) for i, (v, _) in enumerate(tracks)]) if tracks \
            else np.zeros(0, dtype=int)
        view = np.concatenate([np.asarray(v, dtype=int) for v, _ in tracks]) if tracks else np.zeros(0, dtype=int)
        pixel = np.concatenate([np.asarray(p, dtype=float).reshape(-1, 2) for _, p in tracks]) if tracks \
            else np.zeros((0, 2))
        return cls(track, view, pixel, len(tracks), n_views)

    def pairs(self) -> dict[tuple[int, int], np.ndarray]:
        """Tracks shared by each pair of views (i < j): the track indices."""
        by_track: dict[int, list[int]] = {}
        for t, v in zip(self.track.tolist(), self.view.tolist()):
            by_track.setdefault(t, []).append(v)
        shared: dict[tuple[int, int], list[int]] = {}
        for t, views in by_track.items():
            views = sorted(views)
            for a in range(len(views)):
                for b in range(a + 1, len(views)):
                    shared.setdefault((views[a], views[b]), []).append(t)
        return {key: np.array(value) for key, value in shared.items()}

    def lookup(self) -> dict[tuple[int, int], int]:
        """(track, view) -> observation index."""
        return {(t, v): m for m, (t, v) in enumerate(zip(self.track.tolist(), self.view.tolist()))}


def hartley(pixels: np.ndarray) -> np.ndarray:
    """The similarity (3x3) taking points to centroid 0 and mean distance sqrt 2 (Hartley 1997):
    what keeps the linear estimates (fundamental matrix, DLT) well conditioned."""
    centre = pixels.mean(axis=0)
    spread = np.mean(np.linalg.norm(pixels - centre, axis=1))
    scale = np.sqrt(2.0) / spread if spread > 0 else 1.0
    return np.array([[scale, 0.0, -scale * centre[0]], [0.0, scale, -scale * centre[1]], [0.0, 0.0, 1.0]])


def apply(T: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    return pixels @ T[:2, :2].T + T[:2, 2]


def project(P: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (k, 2) and depths (k,) of homogeneous points X (k, 4) in camera P."""
    proj = X @ P.T
    with np.errstate(divide="ignore", invalid="ignore"):
        return proj[:, :2] / proj[:, 2:3], proj[:, 2]
