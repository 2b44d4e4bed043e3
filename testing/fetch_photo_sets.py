"""Fetch the public photo sets of testing/photo_sets.py into a data root, each file checked against
the manifest (testing/photo_sets_manifest.json: every file's SHA-256 and size, recorded from the
copies every figure of docs/reconstruction-vs-colmap.md comes from). Standard library and git only;
bench/fetch_photo_sets.py is the command line (``python -m bench.fetch_photo_sets``).

Sets, where they come from, and their owners (credit them when you use them):

- ``templeRing`` and ``templeSparseRing``: Middlebury multi-view stereo data (Seitz, Curless,
  Diebel, Scharstein and Szeliski, "A comparison and evaluation of multi-view stereo reconstruction
  algorithms", CVPR 2006), the zip files templeRing.zip and templeSparseRing.zip of
  https://vision.middlebury.edu/mview/data/data/ (source ``middlebury``: that folder's URL).
  Where that download fails, templeSparseRing is taken from the folder ``templeSparseRing`` of a
  public copy on GitHub, https://github.com/maximm8/VisualHull (source ``visual_hull``: a git URL
  or path), whose files are Middlebury's byte for byte (the same manifest checks them).
- ``sceaux``: "Sceaux Castle", photographs copyright 2012 Pierre Moulon, openMVG's sample data set,
  the folder ``images`` of https://github.com/openMVG/ImageDataset_SceauxCastle (source
  ``sceaux``: a git URL or path). The repository states no licence beyond the copyright notice of
  its Readme.txt: the photos are read, never shipped.
- ``dinoCameras``: the Middlebury "dino" set's ground-truth cameras alone (same authors as above):
  363 views over a hemisphere, ``dino_par.txt`` and its README (no photos), from the folder
  ``dino`` of a public course repository that keeps a copy,
  https://github.com/mervkilcgil/Optimization-of-3-D-Reconstruction-from-Multiple-View-Images
  (source ``dino_cameras``: a git URL or path); that copy's first line names the columns where
  Middlebury's states the count, which the reader skips either way. The autocalibration's
  critical-motion tests and bench.determinacy read it as a general motion.
- ``kittiStraight`` and ``kittiTurn``: KITTI odometry benchmark excerpts (Geiger, Lenz and Urtasun,
  CVPR 2012; CC BY-NC-SA 3.0, non-commercial), the folders KITTI_sequence_1 and KITTI_sequence_2
  (image_l, calib.txt, poses.txt) of https://github.com/niconielsen32/VisualSLAM (source
  ``kitti``: a git URL or path).

Each source is overridable: an argument (``sources``), else the environment variable
GEOCERT_FETCH_MIDDLEBURY, GEOCERT_FETCH_SCEAUX, GEOCERT_FETCH_KITTI, GEOCERT_FETCH_DINO_CAMERAS or
GEOCERT_FETCH_VISUAL_HULL, else the public address.
Only the files the manifest names are taken (a git source's other files are not even downloaded:
a shallow, blob-less clone checks out those paths alone), laid out as photo_sets reads them. The
set is written in a temporary folder inside the data root and renamed into place once every file
matches the manifest: a fetch that fails or is interrupted leaves no set folder behind, and a set
that differs from the manifest in any file (missing, another size, another hash) is refused with
the file named.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import tempfile
import urllib.request
import zipfile
from pathlib import Path

MANIFEST = Path(__file__).with_name("photo_sets_manifest.json")

DEFAULT_SOURCES = {
    "middlebury": "https://vision.middlebury.edu/mview/data/data/",
    "sceaux": "https://github.com/openMVG/ImageDataset_SceauxCastle",
    "kitti": "https://github.com/niconielsen32/VisualSLAM",
    "dino_cameras": "https://github.com/mervkilcgil/Optimization-of-3-D-Reconstruction-from-Multiple-View-Images",
    "visual_hull": "https://github.com/maximm8/VisualHull",
}
ENVIRONMENT = {"middlebury": "GEOCERT_FETCH_MIDDLEBURY", "sceaux": "GEOCERT_FETCH_SCEAUX",
               "kitti": "GEOCERT_FETCH_KITTI", "dino_cameras": "GEOCERT_FETCH_DINO_CAMERAS",
               "visual_hull": "GEOCERT_FETCH_VISUAL_HULL"}

# Per set: its folder under the data root, its source, and where its files are in that source (the
# zip file's name, or the folder of the git repository); ``mirror``: a git source and folder taken
# when the zip cannot be downloaded (its files checked against the same manifest).
SETS = {
    "templeRing": {"folder": "middlebury_templeRing", "source": "middlebury", "zip": "templeRing.zip"},
    "templeSparseRing": {"folder": "middlebury_templeSparseRing", "source": "middlebury",
                         "zip": "templeSparseRing.zip", "mirror": ("visual_hull", "templeSparseRing")},
    "sceaux": {"folder": "sceaux_castle", "source": "sceaux", "subfolder": "images"},
    "kittiStraight": {"folder": "kitti_sequence_1", "source": "kitti", "subfolder": "KITTI_sequence_1"},
    "kittiTurn": {"folder": "kitti_sequence_2", "source": "kitti", "subfolder": "KITTI_sequence_2"},
    "dinoCameras": {"folder": "middlebury_dino_cameras", "source": "dino_cameras", "subfolder": "dino"},
}


class FetchError(RuntimeError):
    pass


class DownloadError(FetchError):
    """The source could not be reached or read (not a file that differs from the manifest)."""


def file_record(path: Path) -> dict:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return {"sha256": digest.hexdigest(), "size": path.stat().st_size}


def folder_records(directory: Path) -> dict:
    """Every file under ``directory`` (relative POSIX path: its SHA-256 and size)."""
    return {p.relative_to(directory).as_posix(): file_record(p)
            for p in sorted(directory.rglob("*")) if p.is_file()}


def read_manifest(path: Path | None = None) -> dict:
    return json.loads(Path(path or MANIFEST).read_text())


def record_manifest(root: Path, keys=None, path: Path | None = None) -> dict:
    """The manifest of the sets under ``root`` (their files' hashes and sizes), written to ``path``."""
    manifest = read_manifest(path) if Path(path or MANIFEST).exists() else {"sets": {}}
    for key in keys or SETS:
        manifest["sets"].setdefault(key, {})["files"] = folder_records(Path(root) / SETS[key]["folder"])
    Path(path or MANIFEST).write_text(dump_manifest(manifest))
    return manifest


def dump_manifest(manifest: dict) -> str:
    """JSON with one line per file."""
    lines = ["{", f' "about": {json.dumps(manifest.get("about", ""))},', ' "sets": {']
    for i, (key, entry) in enumerate(sorted(manifest["sets"].items())):
        lines.append(f"  {json.dumps(key)}: {{")
        for field in sorted(k for k in entry if k != "files"):
            lines.append(f"   {json.dumps(field)}: {json.dumps(entry[field])},")
        lines.append('   "files": {')
        files = sorted(entry.get("files", {}).items())
        lines += [f"    {json.dumps(name)}: {json.dumps(record, sort_keys=True)}" + ("," if j < len(files) - 1 else "")
                  for j, (name, record) in enumerate(files)]
        lines.append("   }")
        lines.append("  }" + ("," if i < len(manifest["sets"]) - 1 else ""))
    return "\n".join(lines + [" }", "}", ""])


def check(directory: Path, files: dict, key: str) -> None:
    """Refuse (FetchError naming the file) a set whose files differ from the manifest's ``files``."""
    for name, expected in sorted(files.items()):
        path = directory / name
        if not path.is_file():
            raise FetchError(f"photo set {key!r}: {name} is missing from the source (the manifest names it)")
        found = file_record(path)
        if found["size"] != expected["size"]:
            raise FetchError(f"photo set {key!r}: {name} has {found['size']} bytes, the manifest {expected['size']}: "
                             "refused")
        if found["sha256"] != expected["sha256"]:
            raise FetchError(f"photo set {key!r}: {name} has SHA-256 {found['sha256']}, the manifest "
                             f"{expected['sha256']}: refused")


def source_of(name: str, sources: dict | None = None) -> str:
    return (sources or {}).get(name) or os.environ.get(ENVIRONMENT[name]) or DEFAULT_SOURCES[name]


def _from_zip(url: str, files: dict, work: Path, target: Path) -> None:
    archive = work / "download.zip"
    try:
        with urllib.request.urlopen(url, timeout=120) as response, open(archive, "wb") as out:
            shutil.copyfileobj(response, out)
    except OSError as error:
        raise DownloadError(f"cannot download {url}: {error}") from error
    try:
        with zipfile.ZipFile(archive) as zipped:
            members = {m.filename: m for m in zipped.infolist() if not m.is_dir()}
            # The zip holds the set in one top folder (templeRing/...): its files are laid out without it.
            tops = {name.split("/", 1)[0] for name in members}
            strip = len(tops) == 1 and all("/" in name for name in members)
            target.mkdir(parents=True)
            for name, member in members.items():
                relative = name.split("/", 1)[1] if strip else name
                if relative not in files:
                    continue
                with zipped.open(member) as source, open(target / relative, "wb") as out:
                    shutil.copyfileobj(source, out)
    except zipfile.BadZipFile as error:
        raise FetchError(f"{url} is not a readable zip file: {error}") from error


def _git(*args: str) -> None:
    done = subprocess.run(["git", *args], capture_output=True, text=True)
    if done.returncode:
        raise FetchError(f"git {' '.join(args[:3])} ... failed: {done.stderr.strip()[-500:]}")


def _from_git(url: str, subfolder: str, files: dict, work: Path, target: Path) -> None:
    clone = work / "clone"
    # Shallow and blob-less: only the files checked out below are downloaded (a server or a local
    # path that ignores --filter or --depth sends more, with the same result).
    _git("clone", "--quiet", "--depth", "1", "--filter=blob:none", "--no-checkout", url, str(clone))
    paths = [f"{subfolder}/{name}" for name in sorted(files)]
    present = subprocess.run(["git", "-C", str(clone), "ls-tree", "-r", "--name-only", "HEAD", "--", subfolder],
                             capture_output=True, text=True).stdout.split("\n")
    missing = sorted(set(paths) - set(present))
    if missing:
        raise FetchError(f"{missing[0][len(subfolder) + 1:]} is missing from {url} ({subfolder}/; "
                         f"{len(missing)} file(s) the manifest names are not there)")
    _git("-C", str(clone), "checkout", "--quiet", "HEAD", "--", *paths)
    target.mkdir(parents=True)
    for name in files:
        destination = target / name
        destination.parent.mkdir(parents=True, exist_ok=True)
        shutil.move(str(clone / subfolder / name), destination)


def fetch(key: str, root: str | os.PathLike, sources: dict | None = None, manifest: dict | None = None,
          log=print) -> Path:
    """Fetch the set ``key`` into ``root`` (its folder as photo_sets reads it) and return the folder.
    A folder already there is checked against the manifest, never overwritten."""
    if key not in SETS:
        raise FetchError(f"photo set {key!r} cannot be fetched (fetchable: {', '.join(SETS)})")
    spec = SETS[key]
    entry = (manifest or read_manifest())["sets"].get(key)
    if not entry or not entry.get("files"):
        raise FetchError(f"photo set {key!r} has no manifest entry: nothing to check it against")
    files = entry["files"]
    root = Path(root)
    destination = root / spec["folder"]
    if destination.exists():
        check(destination, files, key)
        log(f"{key}: {destination} already there, every file as the manifest says")
        return destination
    root.mkdir(parents=True, exist_ok=True)
    source = source_of(spec["source"], sources)
    with tempfile.TemporaryDirectory(prefix=f".fetch-{spec['folder']}-", dir=root) as work:
        work = Path(work)
        target = work / spec["folder"]
        if "zip" in spec:
            url = source.rstrip("/") + "/" + spec["zip"]
            log(f"{key}: downloading {url}")
            try:
                _from_zip(url, files, work, target)
            except DownloadError as error:
                if "mirror" not in spec:
                    raise
                mirror, subfolder = spec["mirror"]
                log(f"{key}: {error}; cloning {subfolder}/ of {source_of(mirror, sources)} instead")
                shutil.rmtree(target, ignore_errors=True)
                _from_git(source_of(mirror, sources), subfolder, files, work, target)
        else:
            log(f"{key}: cloning {spec['subfolder']}/ of {source}")
            _from_git(source, spec["subfolder"], files, work, target)
        check(target, files, key)
        os.rename(target, destination)
    log(f"{key}: {len(files)} files in {destination}, every one as the manifest says")
    return destination
