"""Synthetic projective reconstructions with known calibration (tests and benchmarks).

The thesis's protocol (section 6.7): 100 points in a cube of side 20 centred at the origin,
cameras at a distance of about 40 looking at it, noise added to the image coordinates, and the
scene moved by a random projective transformation. Here each camera of the reconstruction is
resected (DLT) from the noisy image points and the projective points, so the input carries the
noise as a real projective reconstruction would.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Scene:
    cameras: np.ndarray  # (m, 3, 4) projective, the input
    points: np.ndarray  # (n, 4) projective, the input frame
    K: np.ndarray
    rotations: np.ndarray  # (m, 3, 3) true
    centres: np.ndarray  # (m, 3)
    metric_points: np.ndarray  # (n, 3)
    projective: np.ndarray  # Hp: input = metric moved by Hp (cameras P Hp, points Hp^-1 X)
    image_size: tuple[int, int]

    @property
    def plane_at_infinity(self) -> np.ndarray:
        """The true plane at infinity in the input frame, scaled to unit norm."""
        plane = self.projective.T @ np.array([0.0, 0.0, 0.0, 1.0])
        return plane / np.linalg.norm(plane)

    def job_data(self, with_points: bool = True) -> dict:
        data = {"cameras": self.cameras.tolist(), "image_size": list(self.image_size)}
        if with_points:
            data["points"] = self.points.tolist()
        return data


def look_at(centre: np.ndarray, target: np.ndarray, rng: np.random.Generator, up: np.ndarray | None = None
            ) -> np.ndarray:
    z = target - centre
    z /= np.linalg.norm(z)
    up = rng.normal(size=3) if up is None else up
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    return np.vstack([x, np.cross(z, x), z])


def dlt_resection(points3: np.ndarray, image: np.ndarray) -> np.ndarray:
    """The camera minimising the algebraic error of x ~ P X (homogeneous X, normalised data)."""
    mu = image.mean(axis=0)
    s = np.sqrt(2) / np.sqrt(((image - mu) ** 2).sum(axis=1).mean())
    T = np.array([[s, 0, -s * mu[0]], [0, s, -s * mu[1]], [0, 0, 1]])
    X = points3 / np.linalg.norm(points3, axis=1)[:, None]
    x = image * s - s * mu
    rows = []
    for Xi, (u, v) in zip(X, x):
        rows.append(np.concatenate([np.zeros(4), -Xi, v * Xi]))
        rows.append(np.concatenate([Xi, np.zeros(4), -u * Xi]))
    _, _, vt = np.linalg.svd(np.array(rows))
    return np.linalg.inv(T) @ vt[-1].reshape(3, 4)


def make_scene(views: int, noise_percent: float = 0.0, points: int = 100, seed: int = 0,
               K: np.ndarray | None = None, image_size: tuple[int, int] = (1000, 1000),
               grid_points: np.ndarray | None = None, motion: str = "sphere") -> Scene:
    """``motion``: "sphere" (cameras all round, the thesis's), "ring" (a turntable) or
    "translation" (one orientation): the last two are critical motions for constant intrinsics."""
    rng = np.random.default_rng(seed)
    if K is None:
        K = np.array([[1000.0, 0.0, 500.0], [0.0, 1000.0, 500.0], [0.0, 0.0, 1.0]])
    X = grid_points if grid_points is not None else rng.uniform(-10, 10, size=(points, 3))
    rotations, centres, cams = [], [], []
    for index in range(views):
        if motion == "ring":  # a turntable: centres on a circle, every rotation about the y axis
            angle = 2 * np.pi * index / views
            centre = 40 * np.array([np.sin(angle), 0.0, np.cos(angle)])
            R = look_at(centre, np.zeros(3), rng, up=np.array([0.0, 1.0, 0.0]))
        elif motion == "translation":  # one orientation, centres spread over a plane facing the cube
            centre = np.array([*rng.uniform(-15, 15, size=2), -40.0])
            R = np.eye(3)
        else:
            direction = rng.normal(size=3)
            centre = 40 * direction / np.linalg.norm(direction)
            R = look_at(centre, rng.normal(scale=2.0, size=3), rng)
        rotations.append(R)
        centres.append(centre)
        cams.append(K @ np.hstack([R, -(R @ centre)[:, None]]))
    Hp = np.eye(4)
    Hp[:3, :3] += 0.3 * rng.normal(size=(3, 3))
    Hp[:3, 3] = rng.normal(size=3)
    Hp[3, :3] = 0.03 * rng.normal(size=3)
    Xh = np.hstack([X, np.ones((len(X), 1))])
    Xin = Xh @ np.linalg.inv(Hp).T
    sigma = noise_percent / 100.0 * max(image_size)
    inputs = []
    for P in cams:
        x = Xh @ P.T
        x = x[:, :2] / x[:, 2:3]
        if sigma > 0:
            x = x + rng.normal(scale=sigma, size=x.shape)
            Pin = dlt_resection(Xin, x)
        else:
            Pin = P @ Hp
        inputs.append(Pin / np.linalg.norm(Pin))
    return Scene(np.array(inputs), Xin / np.linalg.norm(Xin, axis=1)[:, None], K, np.array(rotations),
                 np.array(centres), X, Hp, image_size)


def from_cameras(cameras: np.ndarray, box: tuple[np.ndarray, np.ndarray], noise_px: float, seed: int = 0,
                 points: int = 100, image_size: tuple[int, int] = (640, 480)) -> Scene:
    """A projective reconstruction of real cameras (m, 3, 4; pixels, e.g. a dataset's ground
    truth): ``points`` points drawn in the box they look at, projected, ``noise_px`` pixels of
    noise added, each camera resected (DLT) from its noisy points in a random projective frame, as
    make_scene does. The scene is first moved by a similarity (centred, the box's half-diagonal
    10) so that the random frame is of the same size whatever the dataset's units."""
    rng = np.random.default_rng(seed)
    lo, hi = (np.asarray(b, dtype=float) for b in box)
    centre, scale = (lo + hi) / 2, 10.0 / (np.linalg.norm(hi - lo) / 2)
    S = np.diag([scale, scale, scale, 1.0])
    S[:3, 3] = -scale * centre
    metric = np.array([P @ np.linalg.inv(S) for P in cameras])
    X = (rng.uniform(lo, hi, size=(points, 3)) - centre) * scale
    Ks, rotations, centres = [], [], []
    from scipy.linalg import rq

    for P in metric:
        K, R = rq(P[:, :3] * np.sign(np.linalg.det(P[:, :3])))
        D = np.diag(np.sign(np.diag(K)))
        Ks.append((K @ D) / (K @ D)[2, 2])
        rotations.append(D @ R)
        centres.append(-np.linalg.solve(P[:, :3], P[:, 3]))
    Hp = np.eye(4)
    Hp[:3, :3] += 0.3 * rng.normal(size=(3, 3))
    Hp[:3, 3] = rng.normal(size=3)
    Hp[3, :3] = 0.03 * rng.normal(size=3)
    Xh = np.hstack([X, np.ones((points, 1))])
    Xin = Xh @ np.linalg.inv(Hp).T
    inputs = []
    for P in metric:
        x = Xh @ P.T
        x = x[:, :2] / x[:, 2:3] + rng.normal(scale=noise_px, size=(points, 2))
        Pin = dlt_resection(Xin, x) if noise_px > 0 else P @ Hp
        inputs.append(Pin / np.linalg.norm(Pin))
    return Scene(np.array(inputs), Xin / np.linalg.norm(Xin, axis=1)[:, None], Ks[0], np.array(rotations),
                 np.array(centres), X, Hp, image_size)


def orthogonal_grids(size: int = 5, spacing: float = 4.0) -> tuple[np.ndarray, list[list[int]]]:
    """Three mutually orthogonal size x size grids (thesis Table 6.2) and their lines (indices
    of the points on each grid line)."""
    ticks = (np.arange(size) - (size - 1) / 2) * spacing
    points, lines = [], []
    for plane in range(3):
        start = len(points)
        for i, a in enumerate(ticks):
            for j, b in enumerate(ticks):
                p = np.zeros(3)
                axes = [k for k in range(3) if k != plane]
                p[axes[0]], p[axes[1]] = a, b
                p[plane] = -((size - 1) / 2) * spacing - spacing  # the grids sit on three faces
                points.append(p)
        for i in range(size):
            lines.append([start + i * size + j for j in range(size)])
            lines.append([start + j * size + i for j in range(size)])
    return np.array(points), lines


def table71_scene(seed: int, noise_percent: float = 0.2, varying_focal: bool = False, views: int = 12,
                  points: int = 15) -> tuple[Scene, list[np.ndarray]]:
    """Thesis Table 7.1's protocol: 15 points in [-1, 1]^3, 12 cameras at distance 2 looking at
    the origin, K = I (or diag(f, f, 1) with f in [0.05, 1] per view), noise of noise_percent of
    the image size (2 units: the image of K = I spans about [-1, 1]) before the reconstruction
    (each camera resected from the noisy image points), a random projective frame. Returns the
    scene (scene.K the first view's) and every view's K."""
    rng = np.random.default_rng(seed)
    X = rng.uniform(-1, 1, size=(points, 3))
    Xh = np.hstack([X, np.ones((points, 1))])
    Hp = np.eye(4)
    Hp[:3, :3] += 0.3 * rng.normal(size=(3, 3))
    Hp[:3, 3] = rng.normal(size=3)
    Hp[3, :3] = 0.1 * rng.normal(size=3)
    Xin = Xh @ np.linalg.inv(Hp).T
    rotations, centres, inputs, Ks = [], [], [], []
    sigma = noise_percent / 100.0 * 2.0
    for _ in range(views):
        direction = rng.normal(size=3)
        centre = 2.0 * direction / np.linalg.norm(direction)
        R = look_at(centre, rng.normal(scale=0.1, size=3), rng)
        f = rng.uniform(0.05, 1.0) if varying_focal else 1.0
        K = np.diag([f, f, 1.0])
        P = K @ np.hstack([R, -(R @ centre)[:, None]])
        x = Xh @ P.T
        x = x[:, :2] / x[:, 2:3]
        if sigma > 0:
            x = x + rng.normal(scale=sigma * (f if varying_focal else 1.0), size=x.shape)
            Pin = dlt_resection(Xin, x)
        else:
            Pin = P @ Hp
        rotations.append(R)
        centres.append(centre)
        inputs.append(Pin / np.linalg.norm(Pin))
        Ks.append(K)
    scene = Scene(np.array(inputs), Xin / np.linalg.norm(Xin, axis=1)[:, None], Ks[0], np.array(rotations),
                  np.array(centres), X, Hp, (2, 2))
    return scene, Ks
