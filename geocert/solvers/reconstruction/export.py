"""Exports of a reconstruction result a user can open elsewhere (pure: dicts in, bytes out).

- COLMAP's text model (https://colmap.github.io/format.html): cameras.txt, images.txt and
  points3D.txt in a zip. One COLMAP camera per registered view. The model is chosen from K:
  SIMPLE_PINHOLE (f, cx, cy) when fx = fy and the skew is 0 (what the "simple" and "varying"
  adjustments return), PINHOLE (fx, fy, cx, cy) otherwise when the skew is 0; COLMAP has no
  model with skew, so a K with skew is written as PINHOLE without it and the file's header says
  so. Image poses are the world-to-camera rotation as a quaternion (qw, qx, qy, qz) and t.
  Point and image ids start at 1; a point's track lists (image id, index of the observation in
  that image's 2D list). Reprojection error per point: the RMS of its residuals, pixels. Image
  names are the views' names made safe for the file (``colmap_names``).
- PLY (ASCII or binary little-endian): the points as vertices with x, y, z and the point's cost
  and certified flag as properties.
"""

from __future__ import annotations

import io
import re
import struct
import zipfile

import numpy as np
from scipy.spatial.transform import Rotation

FORMATS = ("colmap", "ply")


_UNSAFE = re.compile(r"[^A-Za-z0-9._-]")


def colmap_names(cameras: list[dict]) -> dict[int, str]:
    """Each camera's image name as images.txt may hold it: one token on its line, naming a file
    in the image folder. A character other than a letter, digit, '.', '_' or '-' (a space, a line
    break that would start a record of its own, a path separator) becomes '_', a leading '.' too
    (no '..' or hidden file), and a name taken already gets '-<view>'; no name: view<NNNN>."""
    names: dict[int, str] = {}
    taken: set[str] = set()
    for c in cameras:
        given = c.get("name") or ""
        name = re.sub(r"^\.", "_", _UNSAFE.sub("_", given))[:200] or f"view{c['view']:04d}"
        if name in taken:
            name = f"{name}-{c['view']}"
        taken.add(name)
        names[c["view"]] = name
    return names


def _camera_line(camera_id: int, camera: dict) -> tuple[str, str | None]:
    K = np.array(camera["K"], dtype=float)
    w, h = camera["image_size"] if camera.get("image_size") else (2 * K[0, 2], 2 * K[1, 2])
    fx, fy, s, cx, cy = K[0, 0], K[1, 1], K[0, 1], K[0, 2], K[1, 2]
    note = None
    if abs(s) > 1e-9 * fx:
        note = f"# camera {camera_id}: skew {s:.6g} px dropped (COLMAP has no camera model with skew)"
    if abs(fx - fy) <= 1e-12 * fx and note is None:
        return f"{camera_id} SIMPLE_PINHOLE {int(round(w))} {int(round(h))} {fx:.17g} {cx:.17g} {cy:.17g}", note
    return f"{camera_id} PINHOLE {int(round(w))} {int(round(h))} {fx:.17g} {fy:.17g} {cx:.17g} {cy:.17g}", note


def colmap_files(result: dict) -> dict[str, str]:
    """cameras.txt, images.txt and points3D.txt of a reconstruction result."""
    cameras = [c for c in result["cameras"] if c.get("registered") and c.get("K") is not None and c.get("R") is not None]
    image_id = {c["view"]: k + 1 for k, c in enumerate(cameras)}
    camera_lines, notes = [], []
    for c in cameras:
        line, note = _camera_line(image_id[c["view"]], c)
        camera_lines.append(line)
        if note:
            notes.append(note)
    points = [p for p in result["points"] if p.get("point") is not None and not p.get("at_infinity")]
    # Each image's 2D points, in order, and where each 3D point's observations sit among them.
    keypoints: dict[int, list[tuple[float, float, int]]] = {c["view"]: [] for c in cameras}
    tracks: list[list[tuple[int, int]]] = []
    for k, p in enumerate(points):
        track = []
        for view, u, v in p["observations"]:
            view = int(view)
            if view in keypoints:
                track.append((image_id[view], len(keypoints[view])))
                keypoints[view].append((u, v, k + 1))
        tracks.append(track)
    image_lines = []
    names = colmap_names(cameras)
    for c in cameras:
        R = np.array(c["R"], dtype=float)
        x, y, z, w = Rotation.from_matrix(R).as_quat()
        t = c["t"]
        name = names[c["view"]]
        image_lines.append(f"{image_id[c['view']]} {w:.17g} {x:.17g} {y:.17g} {z:.17g} {t[0]:.17g} {t[1]:.17g} "
                           f"{t[2]:.17g} {image_id[c['view']]} {name}")
        image_lines.append(" ".join(f"{u:.17g} {v:.17g} {pid}" for u, v, pid in keypoints[c["view"]]))
    point_lines = []
    for k, (p, track) in enumerate(zip(points, tracks)):
        X = np.array(p["point"], dtype=float)
        residuals = []
        for view, u, v in p["observations"]:
            c = result["cameras"][int(view)]
            cam = np.array(c["R"]) @ X + np.array(c["t"])
            image = np.array(c["K"]) @ cam
            residuals.append((image[0] / image[2] - u) ** 2 + (image[1] / image[2] - v) ** 2)
        error = float(np.sqrt(np.mean(residuals))) if residuals else 0.0
        point_lines.append(f"{k + 1} {X[0]:.17g} {X[1]:.17g} {X[2]:.17g} 128 128 128 {error:.17g} "
                           + " ".join(f"{i} {j}" for i, j in track))
    mean_track = np.mean([len(t) for t in tracks]) if tracks else 0.0
    return {
        "cameras.txt": "\n".join(["# Camera list with one line of data per camera:",
                                  "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]",
                                  f"# Number of cameras: {len(camera_lines)}", *notes, *camera_lines]) + "\n",
        "images.txt": "\n".join(["# Image list with two lines of data per image:",
                                 "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
                                 "#   POINTS2D[] as (X, Y, POINT3D_ID)",
                                 f"# Number of images: {len(cameras)}, mean observations per image: "
                                 f"{(sum(len(k) for k in keypoints.values()) / len(cameras)) if cameras else 0:g}",
                                 *image_lines]) + "\n",
        "points3D.txt": "\n".join(["# 3D point list with one line of data per point:",
                                   "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)",
                                   f"# Number of points: {len(point_lines)}, mean track length: {mean_track:g}",
                                   *point_lines]) + "\n",
    }


def colmap_zip(result: dict) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, text in colmap_files(result).items():
            archive.writestr(name, text)
    return buffer.getvalue()


def ply(result: dict, binary: bool = False) -> bytes:
    """The finite points as a PLY point cloud (x, y, z as doubles; cost; certified as uchar)."""
    points = [p for p in result["points"] if p.get("point") is not None and not p.get("at_infinity")]
    header = "\n".join(["ply", f"format {'binary_little_endian' if binary else 'ascii'} 1.0",
                        "comment geocert reconstruction: certified triangulated points",
                        f"element vertex {len(points)}", "property double x", "property double y", "property double z",
                        "property double cost", "property uchar certified", "end_header"]) + "\n"
    if binary:
        body = b"".join(struct.pack("<ddddB", *p["point"], float(p["cost"] if p["cost"] is not None else float("nan")),
                                    1 if p["certified"] else 0) for p in points)
        return header.encode() + body
    lines = [f"{p['point'][0]:.17g} {p['point'][1]:.17g} {p['point'][2]:.17g} "
             f"{(p['cost'] if p['cost'] is not None else float('nan')):.17g} {1 if p['certified'] else 0}"
             for p in points]
    return (header + "".join(line + "\n" for line in lines)).encode()
