"""The photo sets' fetcher (testing/fetch_photo_sets.py), offline: the Middlebury path from zip
files built here and served by a local HTTP server, the GitHub paths from the local git mirrors
(skipped, saying so, when those are absent), every fetched file checked against the manifest."""

import hashlib
import http.server
import json
import os
import threading
import zipfile
from pathlib import Path

import numpy as np
import pytest

from testing import fetch_photo_sets, photo_sets

MIRRORS = Path(os.environ.get("GEOCERT_MIRRORS", "/work/.mirror"))
KITTI_MIRROR = MIRRORS / "niconielsen32+VisualSLAM" / "repo"
SCEAUX_MIRROR = MIRRORS / "openMVG+ImageDataset_SceauxCastle" / "repo"
DINO_CAMERAS_MIRROR = MIRRORS / "mervkilcgil+Optimization-of-3-D-Reconstruction-from-Multiple-View-Images" / "repo"
VISUAL_HULL_MIRROR = MIRRORS / "maximm8+VisualHull" / "repo"
BENCH_DATA = photo_sets.data_root()


@pytest.fixture
def served(tmp_path):
    """A local HTTP server of the folder ``served`` (its URL), stopped after the test."""
    folder = tmp_path / "served"
    folder.mkdir()

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, directory=str(folder), **kwargs)

        def log_message(self, *args):
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Quiet)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield folder, f"http://127.0.0.1:{server.server_address[1]}/data/"
    server.shutdown()
    server.server_close()


def small_set(seed: int = 0) -> dict:
    """A made-up Middlebury-like set: file name -> bytes."""
    rng = np.random.default_rng(seed)
    files = {f"templeSR{i:04d}.png": rng.bytes(3000 + i) for i in range(1, 4)}
    files["templeSR_par.txt"] = b"3\n"
    files["README.txt"] = b"made up\n"
    return files


def write_zip(path: Path, files: dict, top: str = "templeSparseRing") -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(path, "w") as zipped:
        for name, data in files.items():
            zipped.writestr(f"{top}/{name}", data)


def manifest_of(key: str, files: dict) -> dict:
    return {"sets": {key: {"files": {name: {"sha256": hashlib.sha256(data).hexdigest(), "size": len(data)}
                                     for name, data in files.items()}}}}


def leftovers(root: Path) -> list:
    return sorted(p.name for p in root.iterdir()) if root.exists() else []


class TestMiddleburyFromAServedZip:
    def test_the_zip_is_unpacked_without_its_top_folder_and_checked(self, served, tmp_path):
        folder, url = served
        files = small_set()
        # an extra file the manifest does not name is left out
        write_zip(folder / "data" / "templeSparseRing.zip", {**files, "extra.bin": b"x"})
        root = tmp_path / "root"
        where = fetch_photo_sets.fetch("templeSparseRing", root, {"middlebury": url},
                                       manifest_of("templeSparseRing", files), log=lambda *_: None)
        assert where == root / "middlebury_templeSparseRing"
        assert {p.name: p.read_bytes() for p in where.iterdir()} == files
        assert leftovers(root) == ["middlebury_templeSparseRing"]  # no temporary folder left

    def test_the_source_comes_from_the_environment(self, served, tmp_path, monkeypatch):
        folder, url = served
        files = small_set()
        write_zip(folder / "data" / "templeSparseRing.zip", files)
        monkeypatch.setenv("GEOCERT_FETCH_MIDDLEBURY", url)
        where = fetch_photo_sets.fetch("templeSparseRing", tmp_path / "root", None,
                                       manifest_of("templeSparseRing", files), log=lambda *_: None)
        assert sorted(p.name for p in where.iterdir()) == sorted(files)

    def test_a_changed_file_is_refused_by_name_and_nothing_is_left(self, served, tmp_path):
        folder, url = served
        files = small_set()
        changed = dict(files)
        changed["templeSR0002.png"] = b"\x00" + files["templeSR0002.png"][1:]  # same size, another hash
        write_zip(folder / "data" / "templeSparseRing.zip", changed)
        root = tmp_path / "root"
        with pytest.raises(fetch_photo_sets.FetchError, match=r"templeSR0002\.png has SHA-256 .*refused"):
            fetch_photo_sets.fetch("templeSparseRing", root, {"middlebury": url},
                                   manifest_of("templeSparseRing", files), log=lambda *_: None)
        assert leftovers(root) == []

    def test_a_missing_or_resized_file_is_refused_by_name(self, served, tmp_path):
        folder, url = served
        files = small_set()
        write_zip(folder / "data" / "templeSparseRing.zip", {n: d for n, d in files.items() if n != "README.txt"})
        with pytest.raises(fetch_photo_sets.FetchError, match=r"README\.txt is missing"):
            fetch_photo_sets.fetch("templeSparseRing", tmp_path / "a", {"middlebury": url},
                                   manifest_of("templeSparseRing", files), log=lambda *_: None)
        write_zip(folder / "data" / "templeSparseRing.zip", {**files, "templeSR_par.txt": b"30\n"})
        with pytest.raises(fetch_photo_sets.FetchError, match=r"templeSR_par\.txt has 3 bytes, the manifest 2"):
            fetch_photo_sets.fetch("templeSparseRing", tmp_path / "b", {"middlebury": url},
                                   manifest_of("templeSparseRing", files), log=lambda *_: None)
        assert leftovers(tmp_path / "a") == [] and leftovers(tmp_path / "b") == []

    def test_a_broken_download_leaves_nothing(self, served, tmp_path):
        folder, url = served
        files = small_set()
        write_zip(tmp_path / "whole.zip", files)
        (folder / "data").mkdir()
        # cut short, as an interrupted download
        (folder / "data" / "templeSparseRing.zip").write_bytes((tmp_path / "whole.zip").read_bytes()[:-200])
        root = tmp_path / "root"
        with pytest.raises(fetch_photo_sets.FetchError, match="not a readable zip"):
            fetch_photo_sets.fetch("templeSparseRing", root, {"middlebury": url},
                                   manifest_of("templeSparseRing", files), log=lambda *_: None)
        with pytest.raises(fetch_photo_sets.FetchError, match="cannot download"):
            fetch_photo_sets.fetch("templeRing", root, {"middlebury": url},
                                   manifest_of("templeRing", files), log=lambda *_: None)
        assert leftovers(root) == []

    def test_a_folder_already_there_is_checked_not_overwritten(self, tmp_path):
        files = small_set()
        where = tmp_path / "middlebury_templeSparseRing"
        where.mkdir()
        for name, data in files.items():
            (where / name).write_bytes(data)
        fetch_photo_sets.fetch("templeSparseRing", tmp_path, manifest=manifest_of("templeSparseRing", files),
                               log=lambda *_: None)
        (where / "README.txt").write_bytes(b"made up!\n")
        with pytest.raises(fetch_photo_sets.FetchError, match=r"README\.txt has 9 bytes"):
            fetch_photo_sets.fetch("templeSparseRing", tmp_path, manifest=manifest_of("templeSparseRing", files),
                                   log=lambda *_: None)
        assert (where / "README.txt").read_bytes() == b"made up!\n"

    def test_the_real_sparse_ring_from_a_zip_reads_as_the_bench_copy(self, served, tmp_path):
        """The bench's templeSparseRing, zipped as Middlebury publishes it, fetched with the repo's
        manifest, loads to the same photos and cameras."""
        try:
            bench = photo_sets.load("templeSparseRing")
        except photo_sets.MissingSet as missing:
            pytest.skip(str(missing))
        folder, url = served
        files = {p.name: p.read_bytes() for p in bench.directory.iterdir() if p.is_file()}
        write_zip(folder / "data" / "templeSparseRing.zip", files)
        where = fetch_photo_sets.fetch("templeSparseRing", tmp_path, {"middlebury": url}, log=lambda *_: None)
        manifest = fetch_photo_sets.read_manifest()["sets"]["templeSparseRing"]["files"]
        assert fetch_photo_sets.folder_records(where) == manifest
        same_set(photo_sets.load("templeSparseRing", tmp_path), bench)


class TestTheSparseRingFromItsGitCopy:
    """Where Middlebury's zip cannot be downloaded, templeSparseRing comes from the git copy's
    folder, checked against the same manifest; a zip that downloads but differs is refused, not
    replaced by the copy."""

    def git_copy(self, tmp_path: Path, files: dict) -> str:
        import subprocess

        repo = tmp_path / "copy"
        (repo / "templeSparseRing").mkdir(parents=True)
        (repo / "unrelated.m").write_text("not taken\n")
        for name, data in files.items():
            (repo / "templeSparseRing" / name).write_bytes(data)
        for args in (["init", "-q"], ["add", "-A"],
                     ["-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "-m", "copy"]):
            subprocess.run(["git", "-C", str(repo), *args], check=True, capture_output=True)
        return str(repo)

    def test_a_failed_download_falls_back_to_the_copy(self, served, tmp_path):
        _, url = served  # serves no zip: the download fails
        files = small_set()
        sources = {"middlebury": url, "visual_hull": self.git_copy(tmp_path, files)}
        seen = []
        root = tmp_path / "root"
        where = fetch_photo_sets.fetch("templeSparseRing", root, sources, manifest_of("templeSparseRing", files),
                                       log=seen.append)
        assert {p.name: p.read_bytes() for p in where.iterdir()} == files
        assert leftovers(root) == ["middlebury_templeSparseRing"]
        assert any("cannot download" in line and "instead" in line for line in seen)

    def test_a_copy_that_differs_is_refused(self, served, tmp_path):
        _, url = served
        files = small_set()
        copy = self.git_copy(tmp_path, {**files, "templeSR0001.png": b"other"})
        root = tmp_path / "root"
        with pytest.raises(fetch_photo_sets.FetchError, match=r"templeSR0001\.png has 5 bytes"):
            fetch_photo_sets.fetch("templeSparseRing", root, {"middlebury": url, "visual_hull": copy},
                                   manifest_of("templeSparseRing", files), log=lambda *_: None)
        assert leftovers(root) == []

    def test_a_zip_that_differs_is_refused_not_replaced(self, served, tmp_path):
        folder, url = served
        files = small_set()
        write_zip(folder / "data" / "templeSparseRing.zip", {**files, "README.txt": b"changed!\n"})
        copy = self.git_copy(tmp_path, files)
        with pytest.raises(fetch_photo_sets.FetchError, match=r"README\.txt has 9 bytes"):
            fetch_photo_sets.fetch("templeSparseRing", tmp_path / "root", {"middlebury": url, "visual_hull": copy},
                                   manifest_of("templeSparseRing", files), log=lambda *_: None)

    def test_the_public_copy_is_middleburys_files(self, served, tmp_path):
        """The GitHub copy's folder, fetched with the repo's manifest (recorded from Middlebury's
        zip), loads as 16 photos with ground-truth cameras (f 1520 px)."""
        needs(VISUAL_HULL_MIRROR)
        _, url = served
        where = fetch_photo_sets.fetch("templeSparseRing", tmp_path, {"middlebury": url,
                                       "visual_hull": str(VISUAL_HULL_MIRROR)}, log=lambda *_: None)
        manifest = fetch_photo_sets.read_manifest()["sets"]["templeSparseRing"]["files"]
        assert fetch_photo_sets.folder_records(where) == manifest
        fetched = photo_sets.load("templeSparseRing", tmp_path)
        assert len(fetched.names) == 16 and np.allclose(fetched.K[0, 0], 1520.4, atol=0.1)
        try:
            bench = photo_sets.load("templeSparseRing")
        except photo_sets.MissingSet as missing:
            pytest.skip(f"fetched and checked; not compared: {missing}")
        same_set(fetched, bench)


def same_set(fetched: photo_sets.PhotoSet, bench: photo_sets.PhotoSet) -> None:
    assert fetched.names == bench.names
    assert np.array_equal(fetched.K, bench.K)
    assert fetched.truth.keys() == bench.truth.keys()
    for name, camera in bench.truth.items():
        assert np.array_equal(fetched.truth[name].R, camera.R) and np.array_equal(fetched.truth[name].t, camera.t)
        assert np.array_equal(fetched.truth[name].K, camera.K)
    for name in bench.names:
        assert fetched.path(name).read_bytes() == bench.path(name).read_bytes()


def needs(mirror: Path) -> None:
    if not (mirror / "HEAD").exists():
        pytest.skip(f"no local git mirror at {mirror} (GEOCERT_MIRRORS): the GitHub path is not tested offline")


@pytest.mark.parametrize("key, source, mirror", [("kittiStraight", "kitti", KITTI_MIRROR),
                                                  ("kittiTurn", "kitti", KITTI_MIRROR),
                                                  ("sceaux", "sceaux", SCEAUX_MIRROR)])
def test_a_github_set_from_its_mirror_reads_as_the_bench_copy(key, source, mirror, tmp_path):
    needs(mirror)
    where = fetch_photo_sets.fetch(key, tmp_path, {source: str(mirror)}, log=lambda *_: None)
    manifest = fetch_photo_sets.read_manifest()["sets"][key]["files"]
    assert fetch_photo_sets.folder_records(where) == manifest  # exactly the manifest's files, no others
    assert leftovers(tmp_path) == [where.name]
    fetched = photo_sets.load(key, tmp_path)
    try:
        bench = photo_sets.load(key)
    except photo_sets.MissingSet as missing:
        pytest.skip(f"fetched and checked; not compared: {missing}")
    same_set(fetched, bench)


def test_the_dino_cameras_from_their_mirror_read_as_363_cameras_over_a_hemisphere(tmp_path):
    """A camera set with no photos: exactly the manifest's files, read by the Middlebury reader
    as the dino's 363 views (f 3310.4 px) and the box its README states."""
    from geocert.solvers import datasets

    needs(DINO_CAMERAS_MIRROR)
    where = fetch_photo_sets.fetch("dinoCameras", tmp_path, {"dino_cameras": str(DINO_CAMERAS_MIRROR)},
                                   log=lambda *_: None)
    assert fetch_photo_sets.folder_records(where) == fetch_photo_sets.read_manifest()["sets"]["dinoCameras"]["files"]
    views = datasets.load_middlebury(where)
    assert len(views.names) == 363 and views.names[0] == "dino0001.png"
    assert np.allclose(views.K[:, 0, 0], 3310.4) and views.box is not None
    spread = np.linalg.svd(views.centres - views.centres.mean(axis=0), compute_uv=False)
    assert spread[2] > 0.3 * spread[0]  # not one ring (whose centres are flat: 0.001 of their spread)


def test_a_changed_file_in_a_git_source_is_refused(tmp_path):
    """A manifest that differs from the mirror in one file (as a changed upstream file would):
    refused, naming the file, and no set folder is left."""
    needs(SCEAUX_MIRROR)
    manifest = json.loads(json.dumps(fetch_photo_sets.read_manifest()))
    manifest["sets"]["sceaux"]["files"]["K.txt"]["sha256"] = "0" * 64
    with pytest.raises(fetch_photo_sets.FetchError, match=r"'sceaux': K\.txt has SHA-256 .*refused"):
        fetch_photo_sets.fetch("sceaux", tmp_path, {"sceaux": str(SCEAUX_MIRROR)}, manifest, log=lambda *_: None)
    manifest["sets"]["sceaux"]["files"]["nothere.JPG"] = {"sha256": "0" * 64, "size": 1}
    with pytest.raises(fetch_photo_sets.FetchError, match=r"nothere\.JPG is missing from"):
        fetch_photo_sets.fetch("sceaux", tmp_path, {"sceaux": str(SCEAUX_MIRROR)}, manifest, log=lambda *_: None)
    assert leftovers(tmp_path) == []


def test_the_manifest_is_the_bench_copies():
    """Every set the manifest names, as it is in the bench's data root (where every figure of
    docs/reconstruction-vs-colmap.md comes from), file for file."""
    manifest = fetch_photo_sets.read_manifest()["sets"]
    assert sorted(manifest) == sorted(fetch_photo_sets.SETS)
    for key, spec in fetch_photo_sets.SETS.items():
        assert manifest[key]["credit"] and manifest[key]["files"]
        folder = BENCH_DATA / spec["folder"]
        if folder.exists():
            assert fetch_photo_sets.folder_records(folder) == manifest[key]["files"], key


def test_a_set_that_cannot_be_fetched_says_so(tmp_path):
    with pytest.raises(fetch_photo_sets.FetchError, match="'dinoSparseRing' cannot be fetched"):
        fetch_photo_sets.fetch("dinoSparseRing", tmp_path)
