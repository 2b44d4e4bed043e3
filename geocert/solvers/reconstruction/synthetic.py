"""Synthetic scenes with known calibration for tests, benchmarks and the kind's example: points
in a box seen by cameras on an arc around it, all looking at its centre, with a given K and
optional pixel noise. Tracks are the points' observations in the views that see them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Scene:
    K: np.ndarray
    rotations: np.ndarray  # (n, 3, 3)
    translations: np.ndarray  # (n, 3)
    points: np.ndarray  # (p, 3)
    tracks: list[tuple[np.ndarray, np.ndarray]]  # (views, pixels (k, 2))
    image_size: tuple[int, int]


def look_at(centre: np.ndarray, target: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    z = target - centre
    z = z / np.linalg.norm(z)
    x = np.cross(up, z)
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.array([x, y, z])
    return R, -R @ centre


def scene(views: int = 8, points: int = 60, focal: float = 800.0, image_size=(640, 480), noise_px: float = 0.0,
          spread_degrees: float = 60.0, distance: float = 6.0, seed: int = 0, visibility: float = 1.0) -> Scene:
    """Centres in random directions within ``spread_degrees`` of the -z axis, each camera rolled
    at random about its axis (general motion: a ring or an orbit without roll is a critical
    motion for constant-intrinsics autocalibration, Sturm 1997)."""
    rng = np.random.default_rng(seed)
    w, h = image_size
    K = np.array([[focal, 0.0, w / 2], [0.0, focal, h / 2], [0.0, 0.0, 1.0]])
    X = rng.uniform(-1.0, 1.0, (points, 3))
    rotations, translations = [], []
    for _ in range(views):
        polar = np.radians(spread_degrees) * np.sqrt(rng.uniform())
        azimuth = rng.uniform(0, 2 * np.pi)
        centre = distance * np.array([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth),
                                      -np.cos(polar)])
        R, t = look_at(centre, 0.3 * rng.normal(size=3), rng.normal(size=3))
        rotations.append(R)
        translations.append(t)
    rotations, translations = np.array(rotations), np.array(translations)
    seen = rng.uniform(size=(points, views)) < visibility
    tracks = observed(X, rotations, translations, K, seen, noise_px, rng)
    return Scene(K, rotations, translations, X, tracks, (w, h))


def turntable(views: int = 12, points: int = 80, focal: float = 800.0, image_size=(640, 480), noise_px: float = 0.0,
              step_degrees: float = 10.0, elevation_degrees: float = 20.0, distance: float = 6.0,
              seed: int = 0) -> Scene:
    """An object turning on a turntable before a still camera (the Oxford Dinosaur's motion):
    equivalently the camera's centre on a circle about the vertical axis, looking at the axis
    from a fixed elevation, no roll. Every rotation shares one axis and the centres are coplanar:
    a critical motion for constant intrinsics (Sturm 1997)."""
    rng = np.random.default_rng(seed)
    w, h = image_size
    K = np.array([[focal, 0.0, w / 2], [0.0, focal, h / 2], [0.0, 0.0, 1.0]])
    X = rng.uniform(-1.0, 1.0, (points, 3))
    up = np.array([0.0, -1.0, 0.0])  # image y points down the axis
    rotations, translations = [], []
    elevation = np.radians(elevation_degrees)
    for k in range(views):
        angle = np.radians(step_degrees * k)
        centre = distance * np.array([np.cos(elevation) * np.sin(angle), -np.sin(elevation),
                                      -np.cos(elevation) * np.cos(angle)])
        R, t = look_at(centre, np.zeros(3), up)
        rotations.append(R)
        translations.append(t)
    rotations, translations = np.array(rotations), np.array(translations)
    tracks = []
    for j in range(points):
        vs = np.arange(views)
        cam = X[j] @ rotations.transpose(0, 2, 1) + translations
        image = cam @ K.T
        pixels = image[:, :2] / image[:, 2:3] + noise_px * rng.standard_normal((views, 2))
        tracks.append((vs, pixels))
    return Scene(K, rotations, translations, X, tracks, (w, h))


def ring(views: int = 48, points: int = 400, focal: float = 1500.0, image_size=(640, 480), noise_px: float = 0.0,
         elevation_degrees: float = 25.0, distance: float = 6.0, visible_degrees: float = 60.0,
         seed: int = 0) -> Scene:
    """A dense ring of photos round an object (Middlebury's templeRing: 47 photos 7.5 degrees
    apart, a long lens): camera centres evenly on a circle about the vertical axis, looking at
    the axis from a fixed elevation, no roll. The points lie on a sphere of radius 1 and are seen
    only from within ``visible_degrees`` of their outward normal (the object hides its far
    side), so each point is tracked over a stretch of the ring and the views link only to their
    neighbours round it."""
    rng = np.random.default_rng(seed)
    w, h = image_size
    K = np.array([[focal, 0.0, w / 2], [0.0, focal, h / 2], [0.0, 0.0, 1.0]])
    normal = rng.normal(size=(points, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    X = normal.copy()
    up = np.array([0.0, -1.0, 0.0])
    elevation = np.radians(elevation_degrees)
    rotations, translations, centres = [], [], []
    for k in range(views):
        angle = 2 * np.pi * k / views
        centre = distance * np.array([np.cos(elevation) * np.sin(angle), -np.sin(elevation),
                                      -np.cos(elevation) * np.cos(angle)])
        R, t = look_at(centre, np.zeros(3), up)
        rotations.append(R)
        translations.append(t)
        centres.append(centre)
    rotations, translations, centres = np.array(rotations), np.array(translations), np.array(centres)
    towards = centres[None, :, :] - X[:, None, :]
    towards /= np.linalg.norm(towards, axis=2, keepdims=True)
    seen = np.einsum("pi,pvi->pv", normal, towards) > np.cos(np.radians(visible_degrees))
    tracks = observed(X, rotations, translations, K, seen, noise_px, rng)
    return Scene(K, rotations, translations, X, tracks, (w, h))


def observed(X, rotations, translations, K, seen, noise_px: float, rng) -> list:
    """Each point's track: the views ``seen`` marks (at least two), its pixels there with
    Gaussian noise of ``noise_px`` drawn from ``rng`` in point order."""
    tracks = []
    for j in range(len(X)):
        vs = np.flatnonzero(seen[j])
        if len(vs) < 2:
            continue
        cam = X[j] @ rotations[vs].transpose(0, 2, 1) + translations[vs]
        image = cam @ K.T
        pixels = image[:, :2] / image[:, 2:3] + noise_px * rng.standard_normal((len(vs), 2))
        tracks.append((vs, pixels))
    return tracks
