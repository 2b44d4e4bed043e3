"""COLMAP (pycolmap, the ``bench`` extra) on a list of photos, in a child process so that its CPU
time (every thread) is measured and a run past its time limit can be stopped; results cached in
a JSON file under the data root, keyed by the photos (names, order and bytes), pycolmap's
version and the options used.

What runs is COLMAP's default pipeline on the CPU: SIFT extraction (``extract_features``, camera
mode AUTO, SIMPLE_RADIAL with EXIF focal length when the photo has one, else 1.2 x the larger
side), exhaustive matching with two-view geometric verification (``match_exhaustive``), and
incremental mapping (``incremental_mapping``). With a known K the camera is PINHOLE with K's
entries, shared by every photo, and the mapper refines none of them.

    python -m bench.colmap_baseline SPEC.json OUT.json     # what the parent runs (one COLMAP run)
"""

from __future__ import annotations

import hashlib
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

CACHE_NAME = "colmap_cache.json"


def version() -> str:
    import pycolmap

    return pycolmap.__version__


def photos_key(photo_set, names: list[str]) -> str:
    """The photos in their order: names and a SHA-1 of their bytes (a set whose files were
    replaced no longer matches its cached results)."""
    digest = hashlib.sha1()
    for name in names:
        digest.update(photo_set.path(name).read_bytes())
    return f"{len(names)} photos|{'|'.join(names)}|sha1 {digest.hexdigest()}"


def options_key(known_K, model: str | None = None) -> str:
    """What the result depends on besides the photos and their order (``model``: a camera model
    other than COLMAP's default with K unknown, e.g. "SIMPLE_PINHOLE")."""
    camera = ("PINHOLE fixed " + ",".join(f"{v:.6g}" for v in known_K) if known_K is not None
              else model if model else "defaults")
    try:
        which = version()
    except ImportError:  # not installed: any version's cached result answers (see cached)
        which = ANY_VERSION
    return f"pycolmap {which}; extract_features AUTO, match_exhaustive, incremental_mapping, cpu; camera {camera}"


ANY_VERSION = "(any version)"


def stage_images(photo_set, names: list[str], directory: Path) -> None:
    """The photos COLMAP reads: links to the published files; a format the reconstruction kind
    does not read (PGM) converted losslessly to PNG, so both read the same pixels."""
    import cv2

    for name in names:
        source = photo_set.path(name)
        target = directory / png_name(name)
        if target.name == name:
            target.symlink_to(source)
        else:
            cv2.imwrite(str(target), cv2.imread(str(source), cv2.IMREAD_UNCHANGED))


def png_name(name: str) -> str:
    return name if Path(name).suffix.lower() in (".png", ".jpg", ".jpeg") else name + ".png"


def run_in_child(photo_set, names: list[str], known_K, timeout_s: float, model: str | None = None) -> dict:
    """One COLMAP run in a child process: its result (see reconstruct) with wall and CPU seconds
    (the child's user + system time, every thread), or {"error": ...}."""
    with tempfile.TemporaryDirectory(prefix="colmap-bench-") as work:
        work = Path(work)
        (work / "images").mkdir()
        stage_images(photo_set, names, work / "images")
        spec = {"images": str(work / "images"), "names": [png_name(n) for n in names], "work": str(work),
                "K": None if known_K is None else [float(v) for v in known_K], "model": model}
        (work / "spec.json").write_text(json.dumps(spec))
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        try:
            done = subprocess.run([sys.executable, "-m", "bench.colmap_baseline", str(work / "spec.json"),
                                   str(work / "out.json")], timeout=timeout_s, capture_output=True, text=True,
                                  cwd=Path(__file__).resolve().parents[1])
        except subprocess.TimeoutExpired:
            return {"error": f"time limit {timeout_s:.0f} s", "wall_s": time.perf_counter() - start}
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        if done.returncode != 0 or not (work / "out.json").exists():
            return {"error": f"exit {done.returncode}: {done.stderr.strip()[-500:]}", "wall_s": wall, "cpu_s": cpu}
        result = json.loads((work / "out.json").read_text())
        renamed = {n: png_name(n) for n in names}
        result["cameras"] = {n: result["cameras"][p] for n, p in renamed.items() if p in result["cameras"]}
        return {**result, "wall_s": wall, "cpu_s": cpu}


def reconstruct(images: str, names: list[str], work: str, known_K, camera_model: str | None = None) -> dict:
    """COLMAP on the photos (see the module's docstring): the largest model's cameras per photo
    name (K, R, t as x = K [R | t] X; distortion ignored), points, models, CPU per stage.
    ``camera_model`` (K unknown): the camera model instead of COLMAP's default (SIMPLE_RADIAL), e.g.
    "SIMPLE_PINHOLE" (one focal length, no distortion: geocert's "simple")."""
    import pycolmap

    work = Path(work)
    database = work / "database.db"
    reader = pycolmap.ImageReaderOptions()
    mode = pycolmap.CameraMode.AUTO
    mapper = pycolmap.IncrementalPipelineOptions()
    if known_K is not None:
        fx, fy, cx, cy = known_K
        reader.camera_model, reader.camera_params = "PINHOLE", f"{fx},{fy},{cx},{cy}"
        mode = pycolmap.CameraMode.SINGLE
        mapper.ba_refine_focal_length = mapper.ba_refine_principal_point = mapper.ba_refine_extra_params = False
    elif camera_model:
        reader.camera_model = camera_model
    cpu = {}
    mark = time.process_time()
    pycolmap.extract_features(database, images, image_names=names, camera_mode=mode, reader_options=reader,
                              device=pycolmap.Device.cpu)
    cpu["extract"], mark = time.process_time() - mark, time.process_time()
    pycolmap.match_exhaustive(database, device=pycolmap.Device.cpu)
    cpu["match"], mark = time.process_time() - mark, time.process_time()
    (work / "sparse").mkdir(exist_ok=True)
    models = pycolmap.incremental_mapping(database, images, work / "sparse", mapper)
    cpu["map"] = time.process_time() - mark
    sizes = sorted((m.num_reg_images() for m in models.values()), reverse=True)
    cameras, points = {}, 0
    if models:
        model = max(models.values(), key=lambda m: m.num_reg_images())
        points = model.num_points3D()
        for image in model.images.values():
            if not image.has_pose:
                continue
            pose = image.cam_from_world()
            cameras[image.name] = {"K": image.camera.calibration_matrix().tolist(),
                                   "R": pose.rotation.matrix().tolist(), "t": np.asarray(pose.translation).tolist(),
                                   "model": image.camera.model.name, "params": list(image.camera.params)}
    return {"cameras": cameras, "points": points, "models": sizes, "cpu_stage_s": cpu}


def cached(root: Path, key: str) -> dict | None:
    """The cached result of ``key``; with pycolmap not installed (ANY_VERSION in the key), the
    newest cached under any version."""
    path = root / CACHE_NAME
    if not path.exists():
        return None
    cache = json.loads(path.read_text())
    if ANY_VERSION not in key:
        return cache.get(key)
    head, tail = key.split(f"pycolmap {ANY_VERSION}")
    found = [value for name, value in cache.items() if name.startswith(head + "pycolmap ") and name.endswith(tail)]
    return found[-1] if found else None


def store(root: Path, key: str, result: dict) -> None:
    path = root / CACHE_NAME
    cache = json.loads(path.read_text()) if path.exists() else {}
    cache[key] = result
    path.write_text(json.dumps(cache, indent=1))


if __name__ == "__main__":
    spec = json.loads(Path(sys.argv[1]).read_text())
    Path(sys.argv[2]).write_text(json.dumps(reconstruct(spec["images"], spec["names"], spec["work"], spec["K"],
                                                            spec.get("model"))))
