"""Jobs as a client submits them, shared by the service tests and the benches."""

from __future__ import annotations

import numpy as np


def service_job(rng, tracks: int, views: int = 4, **options) -> dict:
    cameras = random_cameras(rng, views)
    body_tracks = []
    for _ in range(tracks):
        chosen = sorted(rng.choice(views, size=int(rng.integers(2, views + 1)), replace=False).tolist())
        _, points = noisy_track(rng, cameras[chosen])
        body_tracks.append({"views": chosen, "points": points.tolist()})
    return {"kind": "triangulation", "data": {"cameras": cameras.tolist(), "tracks": body_tracks},
            "options": options}



def random_cameras(rng: np.random.Generator, count: int, spread: float = 2.0) -> np.ndarray:
    return np.array([
        look_at(rng.normal(size=3) * spread + np.array([0.0, 0.0, -8.0]), rng.normal(size=3) * 0.3)
        for _ in range(count)
    ])


def noisy_track(rng: np.random.Generator, cameras: np.ndarray, noise_px: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    X = np.append(rng.normal(size=3), 1.0)
    return X, project(cameras, X) + rng.normal(size=(len(cameras), 2)) * noise_px



def look_at(centre: np.ndarray, target: np.ndarray, focal: float = 800.0) -> np.ndarray:
    """A 3x4 camera K [R | -R c] at ``centre`` looking at ``target`` (640x480 image)."""
    z = target - centre
    z = z / np.linalg.norm(z)
    x = np.cross([0.0, 1.0, 0.0], z)
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    K = np.array([[focal, 0, 320], [0, focal, 240], [0, 0, 1.0]])
    return K @ np.hstack([R, -R @ centre[:, None]])


def project(cameras: np.ndarray, X: np.ndarray) -> np.ndarray:
    proj = cameras @ X
    return proj[:, :2] / proj[:, 2:3]
