"""Synthetic photos with ground truth, for testing the image stage and the K-known path.

A scene is a set of textured rectangles in 3D (by default a box standing on a ground square);
each is drawn into a pinhole camera (K, R, t with x_cam = R X + t) by the homography from its
texture to the image (``cv2.warpPerspective``), occlusion resolved by a z-buffer of the faces'
depths along each pixel's ray. Textures are band-limited noise at several scales (blobs and
corners of many sizes, what SIFT finds).

``Scene.surface_point`` casts a pixel's ray into the scene and returns the first face's point, so
a test can take a track's pixel in one view to the scene and compare its projections in the
others with the track's pixels.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np


@dataclass
class Face:
    origin: np.ndarray  # a corner (3,)
    u: np.ndarray  # edge from the corner (3,); the texture's x axis
    v: np.ndarray  # the other edge (3,); the texture's y axis
    texture: np.ndarray  # grayscale uint8 (rows along v, columns along u)

    @property
    def normal(self) -> np.ndarray:
        n = np.cross(self.u, self.v)
        return n / np.linalg.norm(n)


@dataclass
class Camera:
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray

    @property
    def centre(self) -> np.ndarray:
        return -self.R.T @ self.t

    def project(self, X: np.ndarray) -> np.ndarray:
        h = (np.atleast_2d(X) @ self.R.T + self.t) @ self.K.T
        return h[:, :2] / h[:, 2:3]


@dataclass
class Scene:
    faces: list[Face]
    cameras: list[Camera] = field(default_factory=list)
    image_size: tuple[int, int] = (640, 480)  # (w, h)

    def render(self, camera: Camera, noise_sigma: float = 0.0, seed: int = 0) -> np.ndarray:
        """The grayscale uint8 image of the scene (black background)."""
        w, h = self.image_size
        image = np.zeros((h, w), dtype=np.float32)
        zbuffer = np.full((h, w), np.inf)
        xs, ys = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        rays = np.stack([xs, ys, np.ones_like(xs)], axis=-1) @ np.linalg.inv(camera.K).T  # z = 1
        for face in self.faces:
            th, tw = face.texture.shape
            # texture pixel (x, y) -> plane point origin + (x + 0.5)/tw u + (y + 0.5)/th v
            # (pixel centres at integer coordinates, as OpenCV's warp samples them)
            S = np.array([[1.0 / tw, 0, 0.5 / tw], [0, 1.0 / th, 0.5 / th], [0, 0, 1]])
            H = camera.K @ np.c_[camera.R @ face.u, camera.R @ face.v, camera.R @ face.origin + camera.t] @ S
            warped = cv2.warpPerspective(face.texture.astype(np.float32), H, (w, h), flags=cv2.INTER_LINEAR,
                                         borderMode=cv2.BORDER_CONSTANT, borderValue=-1.0)
            mask = cv2.warpPerspective(np.ones((th, tw), np.float32), H, (w, h), flags=cv2.INTER_NEAREST,
                                       borderMode=cv2.BORDER_CONSTANT, borderValue=0.0) > 0.5
            mask &= warped >= 0
            # Depth of the face's plane along each pixel's ray (a z-buffer: exact occlusion).
            n_c = camera.R @ face.normal
            with np.errstate(divide="ignore", invalid="ignore"):
                depth = (n_c @ (camera.R @ face.origin + camera.t)) / (rays @ n_c)
            mask &= (depth > 0) & (depth < zbuffer)
            image[mask] = warped[mask]
            zbuffer[mask] = depth[mask]
        if noise_sigma > 0:
            image += np.random.default_rng(seed).normal(0.0, noise_sigma, image.shape).astype(np.float32)
        return np.clip(np.rint(image), 0, 255).astype(np.uint8)

    def images(self, noise_sigma: float = 0.0) -> list[np.ndarray]:
        return [self.render(c, noise_sigma, seed=k) for k, c in enumerate(self.cameras)]

    def surface_point(self, camera: Camera, pixel: np.ndarray) -> np.ndarray:
        """The first scene point on the pixel's ray (NaN when the ray meets no face)."""
        ray = camera.R.T @ np.linalg.solve(camera.K, np.r_[pixel, 1.0])
        centre = camera.centre
        best, best_depth = np.full(3, np.nan), np.inf
        for face in self.faces:
            n = np.cross(face.u, face.v)
            denom = n @ ray
            if abs(denom) < 1e-12:
                continue
            depth = n @ (face.origin - centre) / denom
            if not 0 < depth < best_depth:
                continue
            X = centre + depth * ray
            a, b = np.linalg.lstsq(np.c_[face.u, face.v], X - face.origin, rcond=None)[0]
            if 0 <= a <= 1 and 0 <= b <= 1:
                best, best_depth = X, depth
        return best


def noise_texture(size: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """Band-limited noise summed over octaves, stretched to 0..255 (grayscale uint8)."""
    w, h = size
    total = np.zeros((h, w), np.float32)
    for cells, weight in ((4, 1.0), (8, 0.8), (16, 0.7), (32, 0.6), (64, 0.5), (128, 0.35)):
        coarse = rng.uniform(-1, 1, (max(2, h * cells // w), cells)).astype(np.float32)
        total += weight * cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC)
    total -= total.min()
    return (255 * total / max(total.max(), 1e-6)).astype(np.uint8)


def look_at(centre: np.ndarray, target: np.ndarray, up: np.ndarray = np.array([0.0, 0.0, 1.0])) -> tuple[np.ndarray, np.ndarray]:
    """R, t of a camera at ``centre`` looking at ``target`` (image y down, world ``up`` up)."""
    z = target - centre
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.array([x, y, z])
    return R, -R @ centre


def box_scene(n_views: int = 8, image_size: tuple[int, int] = (640, 480), focal: float = 700.0,
              radius: float = 4.0, elevation_deg: float = 30.0, arc_deg: float = 360.0,
              seed: int = 0) -> Scene:
    """A textured box (1 x 0.8 x 0.6) standing on a textured ground square (3 x 3), seen by
    ``n_views`` cameras spread over ``arc_deg`` of a ring round it, each looking at its centre."""
    rng = np.random.default_rng(seed)
    a, b, c = 1.0, 0.8, 0.6
    o = np.array([-a / 2, -b / 2, 0.0])
    ex, ey, ez = np.array([a, 0, 0.0]), np.array([0, b, 0.0]), np.array([0, 0, c])
    tex = lambda: noise_texture((256, 256), rng)  # noqa: E731
    # Edges ordered so that cross(u, v) points out of the box.
    faces = [
        Face(o + ez, ex, ey, tex()),  # top
        Face(o, ex, ez, tex()),  # y = -b/2, normal -y
        Face(o + ey, ez, ex, tex()),  # y = +b/2, normal +y
        Face(o, ey, ez, tex()),  # x = -a/2, normal -x
        Face(o + ex, ey, ez, tex()),  # x = +a/2, normal +x
        Face(np.array([-1.5, -1.5, 0.0]), np.array([3.0, 0, 0]), np.array([0, 3.0, 0]),
             noise_texture((512, 512), rng)),  # ground, normal +z
    ]
    w, h = image_size
    K = np.array([[focal, 0, (w - 1) / 2], [0, focal, (h - 1) / 2], [0, 0, 1.0]])
    target = np.array([0, 0, c / 2])
    cameras = []
    step = np.radians(arc_deg) / (n_views if arc_deg >= 360 else max(n_views - 1, 1))
    el = np.radians(elevation_deg)
    for k in range(n_views):
        az = k * step
        centre = target + radius * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        R, t = look_at(centre, target)
        cameras.append(Camera(K.copy(), R, t))
    return Scene(faces, cameras, image_size)
