"""Issue 14's image stage and K-known path: photos -> tracks -> cameras and points.

Synthetic: a textured box on a textured ground (geocert.solvers.reconstruction.render) seen by a
ring of cameras with known K, R, t. Real: Middlebury's dinoSparseRing (Seitz, Curless, Diebel,
Scharstein and Szeliski, CVPR 2006), 14 photos of an untextured object with ground-truth cameras.
"""

from __future__ import annotations

import base64
import struct
import zlib

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from geocert.core.geometry import InputError
from geocert.pipelines.reconstruction import features
from geocert.solvers.reconstruction import calibrated
from testing.camera_errors import align_rotations, rotation_angle_deg
from geocert.solvers.reconstruction.calibrated import CalibratedOptions, calibrated_reconstruction, refine_cameras
from geocert.pipelines.reconstruction.features import (FeatureOptions, build_tracks, decode_image,
                                                     tracks_from_images)
from geocert.solvers.reconstruction.render import box_scene



def _b64(data: bytes) -> str:
    return base64.b64encode(data).decode()


def _png_header(w: int, h: int) -> bytes:
    """A PNG signature and IHDR chunk claiming w x h (no image data)."""
    ihdr = struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)
    chunk = b"IHDR" + ihdr
    return b"\x89PNG\r\n\x1a\n" + struct.pack(">I", len(ihdr)) + chunk + struct.pack(">I", zlib.crc32(chunk))


# ---------------------------------------------------------------------------------------------
# Decoding


class TestDecode:
    def test_png_and_jpeg_round_trip(self):
        image = (np.arange(40 * 30).reshape(30, 40) % 256).astype(np.uint8)
        ok, png = cv2.imencode(".png", image)
        assert ok
        assert np.array_equal(decode_image(_b64(png.tobytes()), "images/0/content"), image)
        colour = cv2.merge([image, image, image])
        ok, jpg = cv2.imencode(".jpg", colour, [cv2.IMWRITE_JPEG_QUALITY, 95])
        decoded = decode_image("data:image/jpeg;base64," + _b64(jpg.tobytes()), "images/1/content")
        assert decoded.shape == (30, 40) and decoded.dtype == np.uint8
        assert np.abs(decoded.astype(int) - image).mean() < 8

    @pytest.mark.parametrize("content, words", [
        ("", "empty"),
        ("   ", "empty"),
        ("not base64 at all!", "base64"),
        (_b64(b"GIF89a" + bytes(100)), "PNG or JPEG"),
        (_b64(_png_header(100_000, 100_000)), "limits"),
        (_b64(_png_header(9000, 10)), "limits"),
        (_b64(_png_header(8, 8)), "at least"),
        (_b64(_png_header(64, 64)), "could not be decoded"),
        (_b64(b"\xff\xd8\xff\xe0" + bytes(20)), "PNG or JPEG"),
        (12345, "base64 string"),
    ])
    def test_bad_content_names_the_field(self, content, words):
        with pytest.raises(InputError) as caught:
            decode_image(content, "images/3/content")
        assert caught.value.field == "images/3/content"
        assert words in caught.value.reason

    def test_truncated_png(self):
        ok, png = cv2.imencode(".png", np.random.default_rng(0).integers(0, 255, (64, 64), dtype=np.uint8))
        with pytest.raises(InputError) as caught:
            decode_image(_b64(png.tobytes()[:200]), "images/0/content")
        assert caught.value.field == "images/0/content"

    def test_jpeg_size_read_from_its_frame_header(self):
        ok, jpg = cv2.imencode(".jpg", np.zeros((37, 53), np.uint8))
        assert features._jpeg_size(jpg.tobytes()) == (53, 37)


# ---------------------------------------------------------------------------------------------
# Tracks


class TestTrackGroups:
    def test_inconsistent_track_dropped(self):
        # Track A: (0,0)-(1,0)-(2,0) and a wrong match (0,0)-(2,1): view 2 twice -> dropped whole.
        # Track B: (0,1)-(1,1)-(2,2) consistent. Track C: (1,2)-(2,3) (two views, kept).
        matches = {(0, 1): np.array([[0, 0], [1, 1]]), (1, 2): np.array([[0, 0], [1, 2], [2, 3]]),
                   (0, 2): np.array([[0, 1]])}
        kept, counts = build_tracks(matches, [2, 3, 4])
        assert counts == {"tracks_built": 3, "dropped_inconsistent": 1, "dropped_short": 0, "tracks_kept": 2}
        assert kept == [[(0, 1), (1, 1), (2, 2)], [(1, 2), (2, 3)]]

    def test_min_track_length(self):
        matches = {(0, 1): np.array([[0, 0], [1, 1]]), (1, 2): np.array([[0, 0]])}
        kept, counts = build_tracks(matches, [2, 2, 1], min_track_length=3)
        assert kept == [[(0, 0), (1, 0), (2, 0)]]
        assert counts["dropped_short"] == 1

    def test_no_matches_no_tracks(self):
        assert build_tracks({}, [3, 4]) == ([], {"tracks_built": 0, "dropped_inconsistent": 0,
                                                 "dropped_short": 0, "tracks_kept": 0})

    @pytest.mark.parametrize("seed", range(6))
    def test_the_groups_are_a_union_finds(self, seed):
        """Random match graphs (chains across views, repeated matches, features matched twice in a
        view) grouped as a plain union-find over the same links groups them."""
        rng = np.random.default_rng(seed)
        per_view = rng.integers(60, 120, size=int(rng.integers(3, 7))).tolist()
        links = {}
        for _ in range(40):  # scene points seen in 2 or more views, linked view to next view
            views = np.sort(rng.choice(len(per_view), size=int(rng.integers(2, len(per_view) + 1)), replace=False))
            keypoints = [int(rng.integers(0, per_view[v])) for v in views]
            for a in range(len(views) - 1):
                links.setdefault((int(views[a]), int(views[a + 1])), []).append((keypoints[a], keypoints[a + 1]))
        for i in range(len(per_view)):  # wrong matches
            for j in range(i + 1, len(per_view)):
                for _ in range(int(rng.integers(0, 6))):
                    links.setdefault((i, j), []).append((int(rng.integers(0, per_view[i])), int(rng.integers(0, per_view[j]))))
        matches = {pair: np.array(rows) for pair, rows in links.items()}
        nodes = [(v, k) for v, n in enumerate(per_view) for k in range(n)]
        parent = {node: node for node in nodes}

        def find(a):
            while parent[a] != a:
                a = parent[a]
            return a

        linked = set()
        for (i, j), rows in matches.items():
            for a, b in rows.tolist():
                linked.update({(i, a), (j, b)})
                ra, rb = find((i, a)), find((j, b))
                if ra != rb:
                    parent[max(ra, rb)] = min(ra, rb)
        groups = {}
        for node in sorted(linked):
            groups.setdefault(find(node), []).append(node)
        for min_length in (2, 3):
            consistent = [g for g in groups.values() if len({v for v, _ in g}) == len(g)]
            expected = sorted(g for g in consistent if len(g) >= min_length)
            kept, counts = build_tracks(matches, per_view, min_track_length=min_length)
            assert kept == expected
            assert counts == {"tracks_built": len(groups), "dropped_inconsistent": len(groups) - len(consistent),
                              "dropped_short": len(consistent) - len(expected), "tracks_kept": len(expected)}


@pytest.fixture(scope="module")
def box():
    scene = box_scene(n_views=8, arc_deg=150.0, seed=0)
    return scene, scene.images()


@pytest.fixture(scope="module")
def box_tracks(box):
    return tracks_from_images(box[1])


class TestSyntheticTracks:
    def test_tracks_match_ground_truth_projections(self, box, box_tracks):
        scene, _ = box
        stats = box_tracks.stats
        assert box_tracks.image_sizes == [(640, 480)] * 8
        assert min(stats["features_per_image"]) > 500
        assert len(stats["verified_pairs"]) >= 14  # the 7 neighbours and more
        assert stats["tracks_kept"] > 1000
        errors = []
        for views, points in box_tracks.tracks:
            X = scene.surface_point(scene.cameras[views[0]], points[0])
            if np.all(np.isfinite(X)):
                errors += [np.linalg.norm(scene.cameras[v].project(X)[0] - p) for v, p in zip(views[1:], points[1:])]
        errors = np.array(errors)
        # Measured (seed 0): median 0.46 px, 94% within 2 px (the rest: matches near an epipolar
        # line, or across the box's silhouette, which the reconstruction drops as outliers).
        assert np.median(errors) < 0.7
        assert np.mean(errors < 2.0) > 0.88

    def test_callback_stops(self, box):
        seen = []
        result = tracks_from_images(box[1][:3], callback=lambda p: seen.append(p) or p["stage"] == "matches")
        assert result.status == "cancelled" and result.tracks == []
        assert seen[0] == {"stage": "features", "done": 0, "total": 3}
        assert seen[-1]["stage"] == "matches"

    @pytest.mark.parametrize("late", [False, True])
    def test_features_and_matching_stop_at_their_time_limit(self, box, monkeypatch, late):
        """Past options.time_limit_s no more images are read, and no more pairs matched: the
        status says time_limit and where, and the tracks are those of the pairs matched by then
        (no clock was checked: 300 photos matched exhaustively held a solver for as long as that
        took). The clock is the test's: it jumps past the limit when the callback has seen the
        first image read, or the second pair matched."""
        from types import SimpleNamespace

        from geocert.pipelines.reconstruction import features as module

        clock = [0.0]
        monkeypatch.setattr(module, "time", SimpleNamespace(perf_counter=lambda: clock[0]))

        def callback(progress):
            if (progress["stage"], progress["done"]) == (("matches", 2) if late else ("features", 1)):
                clock[0] = 100.0

        result = tracks_from_images(box[1][:4], FeatureOptions(time_limit_s=50.0), callback)
        assert result.status == "time_limit"
        if late:
            assert result.stats["stopped"].startswith("2 of 6 image pairs matched")
            assert len(result.stats["verified_pairs"]) <= 2 and result.tracks
            assert {int(v) for views, _ in result.tracks for v in views} <= {0, 1, 2}
        else:
            assert result.stats["stopped"].startswith("features read of 1 of 4 images")
            assert result.stats["features_per_image"][1:] == [0, 0, 0] and result.tracks == []


class TestThreads:
    """Images are read and pairs matched two at a time (features.in_order_threads): the tracks are
    the same as one at a time, and the results come in the items' order however they finish."""

    def test_tracks_are_those_of_one_thread(self, box, box_tracks, monkeypatch):
        from geocert.pipelines.reconstruction import features as module

        monkeypatch.setattr(module, "FEATURE_THREADS", 1)
        alone = tracks_from_images(box[1])
        assert len(alone.tracks) == len(box_tracks.tracks) > 1000
        for (views, points), (views2, points2) in zip(alone.tracks, box_tracks.tracks):
            assert np.array_equal(views, views2) and np.array_equal(points, points2)
        assert alone.stats["verified_pairs"] == box_tracks.stats["verified_pairs"]
        assert alone.stats["features_per_image"] == box_tracks.stats["features_per_image"]

    def test_results_in_order_a_stop_a_prefix_a_cancel_none(self):
        import time as clock

        from geocert.pipelines.reconstruction import features as module

        def slow_first(item):  # the first item finishes last
            clock.sleep(0.05 if item == 0 else 0.0)
            return item * 10

        assert module.in_order_threads(slow_first, list(range(6)), lambda k: False) == [0, 10, 20, 30, 40, 50]
        assert module.in_order_threads(slow_first, list(range(6)), lambda k: k >= 3) == [0, 10, 20]
        assert module.in_order_threads(slow_first, list(range(6)), lambda k: None if k == 2 else False) is None


def _cluttered(image: np.ndarray, seed: int, amplitude: float = 40.0) -> np.ndarray:
    """The image with one-pixel dots of +-amplitude over its lower half, different in every view:
    fine, high-contrast detail no other view repeats (foliage, gravel, sensor and JPEG noise on a
    high-resolution photo), whose keypoints have SIFT's strongest responses."""
    h = image.shape[0]
    dots = np.random.default_rng(seed).choice([-amplitude, amplitude], size=image[h // 2:].shape)
    out = image.astype(np.float32)
    out[h // 2:] += dots
    return np.clip(out, 0, 255).astype(np.uint8)


def test_a_keypoint_budget_goes_to_the_scales_views_repeat(box):
    """With more keypoints than max_features, the largest-scale are kept: the strongest responses
    (OpenCV's own limit) are the clutter's, and the three views then verified no pair (at most 12
    inliers, 15 needed; on Sceaux Castle a photo under foliage was left unregistered so)."""
    scene, images = box
    views = [0, 1, 2]
    cluttered = [_cluttered(images[v], seed=100 + v) for v in views]
    found = tracks_from_images(cluttered, FeatureOptions(max_features=500))
    assert found.stats["features_per_image"] == [500] * 3
    verified = {tuple(p["views"]): p["inliers"] for p in found.stats["verified_pairs"]}
    assert verified.keys() >= {(0, 1), (1, 2)} and min(verified[(0, 1)], verified[(1, 2)]) >= 30
    errors = []
    for track_views, points in found.tracks:
        X = scene.surface_point(scene.cameras[views[track_views[0]]], points[0])
        if np.all(np.isfinite(X)):
            errors += [np.linalg.norm(scene.cameras[views[v]].project(X)[0] - x)
                       for v, x in zip(track_views[1:], points[1:])]
    assert np.median(errors) < 1.5  # chance matches would be tens of pixels off


def _ring_gap(a: int, b: int, n: int) -> int:
    return min((a - b) % n, (b - a) % n)


@pytest.fixture(scope="module")
def shuffled_ring():
    """16 rendered views round the box, in a shuffled file order: (scene, images, order), image k
    being view order[k] of the ring."""
    scene = box_scene(n_views=16, arc_deg=360.0, seed=0)
    order = np.random.default_rng(0).permutation(16)
    images = scene.images()
    return scene, [images[i] for i in order], order


class TestPairChoice:
    def test_retrieval_finds_the_ring_neighbours_in_any_file_order(self, shuffled_ring):
        # The ring's neighbours (16 pairs one step apart) are all among the pairs retrieval
        # chooses with 2 neighbours an image; the sequential rule reads the file order and, the
        # files shuffled, matches few of them.
        _, images, order = shuffled_ring
        sift = cv2.SIFT_create(nfeatures=1500)
        descriptors = [sift.detectAndCompute(image, None)[1] for image in images]
        options = FeatureOptions(pairs="retrieval", retrieval_neighbours=2)
        pairs, rule = features.candidate_pairs(16, options, descriptors)
        assert rule == "retrieval" and len(pairs) <= 32
        neighbours = {(min(i, j), max(i, j)) for i in range(16) for j in range(16) if _ring_gap(order[i], order[j], 16) == 1}
        assert neighbours <= set(pairs)
        sequential, _ = features.candidate_pairs(16, FeatureOptions(pairs="sequential", neighbour_window=2))
        assert len(neighbours & set(sequential)) < len(neighbours) / 2

    def test_auto_is_exhaustive_up_to_the_limit_then_retrieval(self):
        rng = np.random.default_rng(0)
        descriptors = [rng.random((50, 128)).astype(np.float32) * 100 for _ in range(6)]
        pairs, rule = features.candidate_pairs(6, FeatureOptions(exhaustive_limit=6), descriptors)
        assert rule == "exhaustive" and len(pairs) == 15
        pairs, rule = features.candidate_pairs(6, FeatureOptions(exhaustive_limit=5, retrieval_neighbours=2),
                                               descriptors)
        assert rule == "retrieval" and len(pairs) < 15 and all(i < j for i, j in pairs)

    def test_a_shuffled_ring_registers_every_view(self, shuffled_ring):
        scene, images, order = shuffled_ring
        found = tracks_from_images(images, FeatureOptions(max_features=1500, pairs="retrieval", retrieval_neighbours=3))
        assert found.stats["pairs_chosen_by"] == "retrieval"
        result = calibrated_reconstruction(found.tracks, [scene.cameras[i].K for i in order])
        assert result.stats["registered"] == 16
        _, errors = align_rotations(result.rotations, [scene.cameras[i].R for i in order])
        assert errors.max() < 0.5


def _ratio_matches_row_by_row(d2: np.ndarray, ratio: float, mutual: bool) -> list[list[int]]:
    """The ratio test and mutual check read off their definitions, one row at a time: a row's
    nearest column (the first of equals), kept when strictly nearer than ratio times every other
    column's distance, and (mutual) when the row is the first of the column's nearest rows."""
    kept = []
    for i, row in enumerate(d2):
        j = int(np.argmin(row))
        others = np.delete(row, j)
        second = others.min() if len(others) else np.inf
        if not (np.isfinite(row[j]) and row[j] < ratio ** 2 * second):
            continue
        if mutual and int(np.argmin(d2[:, j])) != i:
            continue
        kept.append([i, j])
    return kept


@pytest.mark.parametrize("seed", range(40))
def test_ratio_matches_follow_their_definition(seed):
    # Small integer distances make ties common (between a row's nearest two, and between rows
    # nearest to one column); infinities are pairs guided matching forbids.
    rng = np.random.default_rng(seed)
    d2 = rng.integers(0, 5, size=(rng.integers(1, 9), rng.integers(1, 9))).astype(np.float32)
    d2[rng.random(d2.shape) < 0.3] = np.inf
    for ratio in (0.8, 1.0):
        for mutual in (True, False):
            found = features._ratio_matches(d2.copy(), ratio, mutual)
            assert found.tolist() == _ratio_matches_row_by_row(d2, ratio, mutual)


@pytest.mark.parametrize("mutual_by_product", [False, True])
@pytest.mark.parametrize("seed", range(12))
def test_matches_are_the_brute_force_mutual_ratio_matches(seed, mutual_by_product, monkeypatch):
    # Integer descriptors as SIFT's: few levels in few dimensions make equal distances common
    # (a row's nearest two, and several rows nearest to one column); 0..255 in 128 as real ones.
    # The mutual test read from the matrix and from the candidate columns' own product (large
    # pairs: features.MUTUAL_BY_PRODUCT), ties included.
    monkeypatch.setattr(features, "MUTUAL_BY_PRODUCT", 0 if mutual_by_product else 10 ** 12)
    rng = np.random.default_rng(seed)
    levels, dims = ((3, 6), (256, 128))[seed % 2]
    a = rng.integers(0, levels, size=(rng.integers(2, 60), dims)).astype(np.float32)
    b = rng.integers(0, levels, size=(rng.integers(2, 60), dims)).astype(np.float32)
    d2 = ((a[:, None, :].astype(np.float64) - b[None, :, :]) ** 2).sum(axis=2)
    for ratio in (0.8, 0.95):
        for mutual in (True, False):
            found = features._match(a, b, FeatureOptions(ratio=ratio, mutual=mutual))
            assert found.tolist() == _ratio_matches_row_by_row(d2, ratio, mutual)


@pytest.mark.parametrize("seed", range(4))
def test_partial_distances_are_exact(seed):
    """|b|^2 - 2 a.b accumulated by BLAS onto the |b|^2 rows is, plus |a|^2, every squared distance
    exactly (float64 brute force), descriptors at OpenCV's extremes (every entry 0 or 255) included:
    every partial sum is an integer below 2^24."""
    rng = np.random.default_rng(seed)
    a = rng.integers(0, 256, size=(rng.integers(2, 300), 128)).astype(np.float32)
    b = rng.integers(0, 256, size=(rng.integers(2, 300), 128)).astype(np.float32)
    a[0], b[0], b[1] = 255.0, 255.0, 0.0
    partial = features._partial_distances(a, -2.0 * b, np.einsum("ij,ij->i", b, b))
    assert partial.dtype == np.float32 and partial.flags.c_contiguous and partial.shape == (len(a), len(b))
    exact = ((a[:, None, :].astype(np.float64) - b[None, :, :]) ** 2).sum(axis=2)
    assert np.array_equal(partial.astype(np.float64) + (a.astype(np.float64) ** 2).sum(axis=1)[:, None], exact)


def test_large_pairs_mutual_test_by_product_gives_the_same_matches(box, monkeypatch):
    """On SIFT's descriptors of the box's views, the mutual test read from the candidate columns'
    product gives the matrix's matches, pair for pair."""
    found = [features.image_features(FeatureOptions(), image) for image in box[1][:4]]
    for i, j in [(0, 1), (0, 2), (1, 3), (2, 3)]:
        monkeypatch.setattr(features, "MUTUAL_BY_PRODUCT", 10 ** 12)
        gathered = features._match(found[i][1], found[j][1], FeatureOptions())
        monkeypatch.setattr(features, "MUTUAL_BY_PRODUCT", 0)
        by_product = features._match(found[i][1], found[j][1], FeatureOptions())
        assert len(gathered) > 50 and np.array_equal(gathered, by_product)


class TestGuidedMatching:
    # Cameras translated along x: F = [e]x with e = (1, 0, 0), epipolar lines are the rows (y_b = y_a).
    F = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])

    def test_epipolar_distances(self):
        d = features.epipolar_distances(self.F, np.array([[10.0, 50.0]]), np.array([[30.0, 80.0], [40.0, 50.5]]))
        assert np.allclose(d, [[30.0, 0.5]])

    def test_candidates_only_near_the_epipolar_line(self):
        # Feature 0 of a: its nearest descriptor in b (feature 0) lies 30 px off its epipolar line;
        # feature 1 lies on it (0.5 px), feature 2 just beyond the threshold (1.2 px). Feature 1 of a
        # has two allowed candidates with nearly equal descriptors: the ratio test refuses it.
        keypoints_a = np.array([[10.0, 50.0], [10.0, 200.0]])
        keypoints_b = np.array([[30.0, 80.0], [40.0, 50.5], [60.0, 51.2], [20.0, 200.2], [90.0, 199.9]])
        desc_a = np.zeros((2, 128), np.float32)
        desc_a[0, 0], desc_a[1, 1] = 100.0, 100.0
        desc_b = np.zeros((5, 128), np.float32)
        desc_b[0, 0], desc_b[1, 0], desc_b[1, 2], desc_b[2, 0] = 99.0, 90.0, 20.0, 100.0
        desc_b[3, 1], desc_b[3, 3], desc_b[4, 1], desc_b[4, 4] = 100.0, 10.0, 100.0, 10.5
        options = FeatureOptions(guided_ratio=0.8, ransac_threshold_px=1.0)
        matches = features.guided_matches(keypoints_a, desc_a, keypoints_b, desc_b, self.F, options)
        assert matches.tolist() == [[0, 1]]
        loose = FeatureOptions(guided_ratio=0.8, ransac_threshold_px=1.0, guided_threshold_px=2.0)
        assert features.guided_matches(keypoints_a, desc_a, keypoints_b, desc_b, self.F, loose).tolist() == [[0, 2]]

    def test_rendered_pairs_gain_matches_that_fit_the_scene(self, box, box_tracks):
        scene, images = box
        guided = tracks_from_images(images, FeatureOptions(guided_ratio=0.8))
        plain = {tuple(p["views"]): p for p in box_tracks.stats["verified_pairs"]}
        strong = [p for p in guided.stats["verified_pairs"] if plain[tuple(p["views"])]["inliers"] >= 30]
        assert strong and all("guided" in p for p in strong)
        assert all("guided" not in p for p in guided.stats["verified_pairs"] if p not in strong)
        # measured (seed 0): 11 pairs from 69-486 inliers to 150-655
        assert all(p["inliers"] > plain[tuple(p["views"])]["inliers"] for p in strong)
        assert guided.stats["tracks_kept"] > box_tracks.stats["tracks_kept"]
        errors = []
        for views, points in guided.tracks:
            X = scene.surface_point(scene.cameras[views[0]], points[0])
            if np.all(np.isfinite(X)):
                errors += [np.linalg.norm(scene.cameras[v].project(X)[0] - p) for v, p in zip(views[1:], points[1:])]
        assert np.median(errors) < 0.7


# ---------------------------------------------------------------------------------------------
# K-known reconstruction


def _centres_error(result, cameras) -> float:
    """Largest camera-centre error after the similarity aligning estimated to true centres, relative
    to the true centres' spread."""
    est = np.array([-R.T @ t for R, t in zip(result.rotations, result.translations)])
    true = np.array([c.centre for c in cameras])
    me, mt = est.mean(0), true.mean(0)
    E, T = est - me, true - mt
    U, S, Vt = np.linalg.svd(T.T @ E)
    D = np.diag([1, 1, np.sign(np.linalg.det(U @ Vt))])
    Q = U @ D @ Vt
    s = np.trace(np.diag(S) @ D) / (E ** 2).sum()
    return float(np.abs(s * E @ Q.T - T).max() / np.abs(T).max())


@pytest.mark.parametrize("degrees", [1e-9, 1e-6, 0.3, 90.0, 179.9])
def test_rotation_angles_are_right_however_small(degrees):
    """The angles align_rotations reports; exact reconstructions are judged by them to 1e-6
    degrees, below what the arccos of the trace resolves (1e-9 degrees read 0)."""
    R = Rotation.from_rotvec(np.radians(degrees) * np.array([0.36, 0.48, 0.8])).as_matrix()
    assert rotation_angle_deg(R) == pytest.approx(degrees, rel=1e-9)
    assert rotation_angle_deg(R.T @ R) < 1e-12


class TestCalibrated:
    def test_exact_tracks_recovered_exactly(self, box):
        scene, _ = box
        rng = np.random.default_rng(1)
        X = rng.uniform([-0.5, -0.4, 0.0], [0.5, 0.4, 0.6], size=(300, 3))
        tracks = []
        for x in X:
            views = np.array([v for v in range(8) if rng.random() < 0.7 or v in (3, 4)])
            tracks.append((views, np.array([scene.cameras[v].project(x)[0] for v in views])))
        result = calibrated_reconstruction(tracks, [c.K for c in scene.cameras])
        assert result.status == "ok" and result.stats["registered"] == 8
        assert result.stats["outliers_removed"] == 0 and result.stats["points"] == 300
        _, errors = align_rotations(result.rotations, [c.R for c in scene.cameras])
        assert errors.max() < 1e-6
        assert _centres_error(result, scene.cameras) < 1e-8
        assert result.stats["rms_reprojection_px"] < 1e-6
        # chirality: every point in front of every camera that sees it
        for (views, _), X_k in zip(tracks, result.points):
            for v in views:
                assert (result.rotations[v] @ X_k + result.translations[v])[2] > 0

    def test_rendered_images(self, box, box_tracks):
        scene, _ = box
        result = calibrated_reconstruction(box_tracks.tracks, [c.K for c in scene.cameras])
        assert result.stats["registered"] == 8 and all(r is None for r in result.reasons)
        _, errors = align_rotations(result.rotations, [c.R for c in scene.cameras])
        # measured: largest 0.048 degrees, RMS reprojection 0.285 px, 89 observations marked outliers
        # (counted after the final restart)
        assert errors.max() < 0.2
        assert _centres_error(result, scene.cameras) < 0.01
        assert result.stats["rms_reprojection_px"] < 0.5
        assert result.stats["outliers_removed"] > 0  # the wrong matches the tracks hold
        assert len(result.inliers) == len(box_tracks.tracks)
        dropped = np.isnan(result.points[:, 0])
        assert all(not inl.any() for inl, d in zip(result.inliers, dropped) if d)
        # every observation kept as an inlier reprojects within the outlier threshold, in front
        limit = CalibratedOptions().max_reprojection_px
        worst = 0.0
        for (views, points), X, inl in zip(box_tracks.tracks, result.points, result.inliers):
            for v, p in zip(views[inl], points[inl]):
                xc = result.rotations[v] @ X + result.translations[v]
                assert xc[2] > 0
                h = scene.cameras[v].K @ xc
                worst = max(worst, float(np.linalg.norm(h[:2] / h[2] - p)))
        assert worst <= limit

    def test_the_adjustment_after_each_view_agrees_with_least_squares(self, box, box_tracks):
        # The Schur solver's few exact Levenberg-Marquardt steps and least_squares' LSMR steps,
        # after each view is added, lead to the same registered views and rotations (the final
        # adjustments, the same in both, end where the tracks put them).
        scene, _ = box
        Ks = [c.K for c in scene.cameras]
        schur = calibrated_reconstruction(box_tracks.tracks, Ks, CalibratedOptions(ba_solver="schur"))
        lsmr = calibrated_reconstruction(box_tracks.tracks, Ks, CalibratedOptions(ba_solver="lsmr"))
        assert [R is not None for R in schur.rotations] == [R is not None for R in lsmr.rotations]
        _, between = align_rotations(schur.rotations, lsmr.rotations)
        _, errors = align_rotations(schur.rotations, [c.R for c in scene.cameras])
        assert between.max() < 0.05 and errors.max() < 0.2
        assert max(schur.stats["ba_nfev"][:-CalibratedOptions().final_rounds]) <= CalibratedOptions().ba_max_iterations

    def test_unlinked_view_has_a_reason(self, box):
        scene, _ = box
        rng = np.random.default_rng(2)
        X = rng.uniform([-0.5, -0.4, 0.0], [0.5, 0.4, 0.6], size=(100, 3))
        tracks = [(np.array([0, 1, 2]), np.array([scene.cameras[v].project(x)[0] for v in (0, 1, 2)])) for x in X]
        result = calibrated_reconstruction(tracks, [c.K for c in scene.cameras[:4]])
        assert result.stats["registered"] == 3
        assert result.rotations[3] is None and result.translations[3] is None
        assert result.reasons[3] == "sees 0 triangulated points; PnP needs 15"
        assert result.reasons[:3] == [None, None, None]

    def test_per_view_figures_say_where_a_view_stopped(self, box):
        # View 4 shares 20 two-view tracks with view 3 (linked, but no point: only one registered
        # view sees them) and 5 three-view tracks with 2 and 3 (points); 5 points are too few for
        # PnP. View 5 shares nothing. Views 0-3 see 100 four-view tracks.
        scene, _ = box
        rng = np.random.default_rng(5)
        X = rng.uniform([-0.5, -0.4, 0.0], [0.5, 0.4, 0.6], size=(125, 3))
        groups = [(0, 1, 2, 3)] * 100 + [(3, 4)] * 20 + [(2, 3, 4)] * 5
        tracks = [(np.array(g), np.array([scene.cameras[v].project(x)[0] for v in g])) for g, x in zip(groups, X)]
        result = calibrated_reconstruction(tracks, [c.K for c in scene.cameras[:6]])
        assert result.stats["registered"] == 4
        per_view = result.stats["per_view"]
        assert [f["view"] for f in per_view] == list(range(6))
        assert [f["tracks"] for f in per_view] == [100, 100, 105, 125, 25, 0]
        assert [f["linked"] for f in per_view] == [100, 100, 105, 105, 25, 0]
        assert [f["points"] for f in per_view] == [100, 100, 105, 105, 5, 0]
        assert [f["registered_by"] for f in per_view][4:] == [None, None]
        assert sorted(f["registered_by"] for f in per_view[:4]) == ["initial pair", "initial pair", "pnp", "pnp"]
        assert result.reasons[4] == "sees 5 triangulated points; PnP needs 15"

    def test_components_merged(self, box):
        # Views 0-3 and 4-7 share only 6 tracks (seen by 2, 3, 4, 5): too few for PnP (15), so one
        # reconstruction stops at a half; merging a second one started in the other half, by the
        # similarity of the 6 points both triangulate, registers all 8 exactly.
        scene, _ = box
        rng = np.random.default_rng(4)
        X = rng.uniform([-0.5, -0.4, 0.0], [0.5, 0.4, 0.6], size=(206, 3))
        groups = [(0, 1, 2, 3)] * 100 + [(4, 5, 6, 7)] * 100 + [(2, 3, 4, 5)] * 6
        tracks = [(np.array(g), np.array([scene.cameras[v].project(x)[0] for v in g])) for g, x in zip(groups, X)]
        Ks = [c.K for c in scene.cameras]
        alone = calibrated_reconstruction(tracks, Ks)
        assert alone.stats["registered"] == 4 and alone.stats["merged"] == []
        # Per view, where it stopped: views 4 and 5 see the 6 linking points (too few for PnP);
        # 6 and 7 share no track with the registered half.
        per_view = {f["view"]: f for f in alone.stats["per_view"]}
        registered_half = [v for v in range(8) if alone.rotations[v] is not None]
        assert registered_half == [0, 1, 2, 3]
        assert [per_view[v]["registered_by"] is not None for v in range(8)] == [True] * 4 + [False] * 4
        assert [per_view[v]["tracks"] for v in range(8)] == [100, 100, 106, 106, 106, 106, 100, 100]
        assert [per_view[v]["linked"] for v in (4, 5, 6, 7)] == [6, 6, 0, 0]
        assert [per_view[v]["points"] for v in (4, 5, 6, 7)] == [6, 6, 0, 0]
        assert all(per_view[v]["points"] == per_view[v]["tracks"] for v in range(4))
        joined = calibrated_reconstruction(tracks, Ks, CalibratedOptions(merge_components=True))
        assert joined.stats["registered"] == 8
        assert joined.stats["merged"][0]["common_points"] == 6
        _, errors = align_rotations(joined.rotations, [c.R for c in scene.cameras])
        # 1e-5: an angle from arccos of the trace cannot resolve much below 1e-6 degrees (one
        # rounding of the trace is ~1e-8 rad); the centres show the fit exact to 1e-8.
        assert errors.max() < 1e-5
        assert _centres_error(joined, scene.cameras) < 1e-8

    def test_refine_cameras_from_a_start(self, box):
        # Exact tracks; cameras given 0.1 degree and 2 mm off (view 0 exact, held as the gauge; the
        # observations then reproject within max_reprojection_px), one left out: the adjustment
        # returns the scene (similarity-aligned).
        scene, _ = box
        rng = np.random.default_rng(6)
        X = rng.uniform([-0.5, -0.4, 0.0], [0.5, 0.4, 0.6], size=(200, 3))
        tracks = []
        for x in X:
            views = np.array([v for v in range(8) if rng.random() < 0.6 or v in (0, 1)])
            tracks.append((views, np.array([scene.cameras[v].project(x)[0] for v in views])))
        Rs, ts = [], []
        for v, c in enumerate(scene.cameras):
            turn = Rotation.from_rotvec(np.radians(0.1) * rng.normal(size=3) / np.sqrt(3)).as_matrix() if v else np.eye(3)
            Rs.append(turn @ c.R)
            ts.append(c.t + (0.002 * rng.normal(size=3) if v else 0.0))
        Rs[5], ts[5] = None, None
        start = [R for R in Rs if R is not None]
        _, before = align_rotations(start, [c.R for v, c in enumerate(scene.cameras) if v != 5])
        assert before.max() > 0.05
        result = refine_cameras(tracks, [c.K for c in scene.cameras], Rs, ts)
        assert result.rotations[5] is None and result.reasons[5] == "no camera given"
        assert result.stats["registered"] == 7 and result.stats["per_view"][0]["registered_by"] == "given"
        _, after = align_rotations([R for R in result.rotations if R is not None],
                                   [c.R for v, c in enumerate(scene.cameras) if v != 5])
        assert after.max() < 1e-5
        assert result.stats["rms_reprojection_px"] < 1e-5
        with pytest.raises(InputError):
            refine_cameras(tracks, [c.K for c in scene.cameras], [scene.cameras[0].R] + [None] * 7,
                           [scene.cameras[0].t] + [None] * 7)

    def test_callback_stops(self, box):
        scene, _ = box
        rng = np.random.default_rng(3)
        X = rng.uniform([-0.5, -0.4, 0.0], [0.5, 0.4, 0.6], size=(60, 3))
        tracks = [(np.arange(4), np.array([scene.cameras[v].project(x)[0] for v in range(4)])) for x in X]
        seen = []
        result = calibrated_reconstruction(tracks, [c.K for c in scene.cameras[:4]],
                                           callback=lambda p: seen.append(p) or p["done"] >= 3)
        assert result.status == "cancelled" and result.stats["registered"] == 3
        assert seen[-1] == {"stage": "registration", "done": 3, "total": 4}

    @pytest.mark.parametrize("tracks, Ks, field", [
        ([(np.array([0, 2]), np.zeros((2, 2)))], [np.eye(3)] * 2, "tracks/0/views"),
        ([(np.array([0, 0]), np.zeros((2, 2)))], [np.eye(3)] * 2, "tracks/0/views"),
        ([(np.array([0, 1]), np.zeros((3, 2)))], [np.eye(3)] * 2, "tracks/0"),
        ([(np.array([0, 1]), np.zeros((2, 2)))], [np.eye(3), -np.eye(3)], "Ks/1"),
        ([(np.array([0, 1]), np.zeros((2, 2)))], [np.eye(3), np.ones((3, 3))], "Ks/1"),
    ])
    def test_bad_input_names_the_item(self, tracks, Ks, field):
        with pytest.raises(InputError) as caught:
            calibrated_reconstruction(tracks, Ks)
        assert caught.value.field == field

    @pytest.mark.parametrize("bad, field", [
        ((np.array([0, 2]), np.zeros((2, 2))), "tracks/3/views"),
        ((np.array([-1, 1]), np.zeros((2, 2))), "tracks/3/views"),
        ((np.array([1, 0, 1]), np.zeros((3, 2))), "tracks/3/views"),
        ((np.array([0, 1]), np.array([[0.0, 1.0], [np.nan, 2.0]])), "tracks/3"),
        ((np.array([0, 1]), np.zeros((2, 3))), "tracks/3"),
    ])
    def test_bad_track_among_good_ones_is_named(self, bad, field):
        # The tracks are checked all at once first: one that does not fit, among many that do,
        # is still the one named.
        good = [(np.array([0, 1]), np.full((2, 2), float(k))) for k in range(6)]
        with pytest.raises(InputError) as caught:
            calibrated_reconstruction(good[:3] + [bad] + good[3:], [np.eye(3)] * 2)
        assert caught.value.field == field

    def test_no_initial_pair(self):
        K = np.diag([500.0, 500.0, 1.0])
        tracks = [(np.array([0, 1]), np.array([[1.0, 2.0], [3.0, 4.0]]))]
        result = calibrated_reconstruction(tracks, [K, K])
        assert result.status == "failed" and result.stats["registered"] == 0
        assert all(r and "share" in r for r in result.reasons)


# ---------------------------------------------------------------------------------------------
# The initial pair and the registration order on synthetic tracks (f = 800 px, 640 x 480, 0.3 px noise)

K800 = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])


def _observe(cameras, X, facing_deg=None, seed=0):
    """Tracks of points X in cameras (R, t): each point in every camera it projects into (and,
    with ``facing_deg``, whose ray meets the point's outward normal within that angle)."""
    rng = np.random.default_rng(seed)
    tracks = []
    for x in X:
        views, pixels = [], []
        for v, (R, t) in enumerate(cameras):
            h = K800 @ (R @ x + t)
            p = h[:2] / h[2]
            centre = -R.T @ t
            ray = (x - centre) / np.linalg.norm(x - centre)
            if h[2] <= 0.1 or not (0 <= p[0] < 640 and 0 <= p[1] < 480):
                continue
            if facing_deg is not None and np.degrees(np.arccos(np.clip(-ray @ x / np.linalg.norm(x), -1, 1))) > facing_deg:
                continue
            views.append(v)
            pixels.append(p + rng.normal(0.0, 0.3, 2))
        if len(views) >= 2:
            tracks.append((np.array(views), np.array(pixels)))
    return tracks


def _ring(n: int, radius: float, points: int, facing_deg: float = 60.0, seed: int = 0):
    """n cameras round a ring of radius 6 looking at a ball of points of the given radius, each
    point seen from within ``facing_deg`` of its outward normal."""
    from geocert.solvers.reconstruction.render import look_at

    rng = np.random.default_rng(seed)
    cameras = [look_at(np.array([6 * np.cos(a), 6 * np.sin(a), 1.0]), np.zeros(3))
               for a in 2 * np.pi * np.arange(n) / n]
    d = rng.normal(size=(points, 3))
    X = d / np.linalg.norm(d, axis=1, keepdims=True) * rng.uniform(0.6, 1.0, (points, 1)) * radius
    return cameras, _observe(cameras, X, facing_deg=facing_deg, seed=seed)


def _registered_errors(result, cameras):
    registered = [v for v in range(len(cameras)) if result.rotations[v] is not None]
    _, errors = align_rotations([result.rotations[v] for v in registered], [cameras[v][0] for v in registered])
    return registered, errors


class TestInitialPair:
    def test_a_dense_ring_starts_from_a_relaxed_angle(self):
        # 24 views 15 degrees apart round a small object: no pair's rays meet at COLMAP's 16
        # degrees median among the candidates sharing the most tracks, so the angle is halved.
        cameras, tracks = _ring(24, 0.5, 300)
        result = calibrated_reconstruction(tracks, [K800] * 24)
        registered, errors = _registered_errors(result, cameras)
        assert len(registered) == 24 and errors.max() < 1.0
        search = result.stats["initial_pair_search"]
        assert search["thresholds"]["relaxations"] >= 1 and search["pair"]["median_angle_deg"] >= 8.0

    def test_a_wide_baseline_ring(self):
        # 8 views 45 degrees apart: each point is seen by two or three of them.
        cameras, tracks = _ring(8, 1.0, 600, facing_deg=80.0)
        result = calibrated_reconstruction(tracks, [K800] * 8)
        registered, errors = _registered_errors(result, cameras)
        assert len(registered) == 8 and errors.max() < 0.5
        assert result.stats["initial_pair_search"]["thresholds"]["relaxations"] == 0

    def test_forward_motion_down_a_corridor(self):
        # 11 cameras stepping 0.5 along a corridor's axis, looking down it, points on its walls:
        # every pair's baseline is straight ahead (|t_z| = 1), which only the last relaxation allows.
        from geocert.solvers.reconstruction.render import look_at

        rng = np.random.default_rng(0)
        cameras = [look_at(np.array([0.0, 0.5 * k, 0.0]), np.array([0.0, 0.5 * k + 10, 0.0])) for k in range(11)]
        side = rng.choice([-1.0, 1.0], 600)
        X = np.c_[2.0 * side, rng.uniform(2, 30, 600), rng.uniform(-1.5, 1.5, 600)]
        result = calibrated_reconstruction(_observe(cameras, X), [K800] * 11)
        registered, errors = _registered_errors(result, cameras)
        assert len(registered) == 11 and errors.max() < 0.2
        assert result.stats["initial_pair_search"]["pair"]["forward_motion"] > 0.95

    def test_no_baseline_gives_the_true_reason(self):
        # Cameras turning about one centre: plenty of shared tracks, no parallax. The reason says
        # so (the pairs share the tracks; their rays meet at 0 degrees), not that none shares tracks.
        from geocert.solvers.reconstruction.render import look_at

        rng = np.random.default_rng(1)
        cameras = [look_at(np.zeros(3), np.array([np.cos(a), np.sin(a), 0.0])) for a in np.radians([0, 5, 10, 15])]
        X = rng.normal(size=(300, 3)) + np.array([10.0, 1.0, 0.0])
        result = calibrated_reconstruction(_observe(cameras, X), [K800] * 4)
        assert result.status == "failed"
        reason = result.stats["reason"]
        assert "median angle 0.0" in reason and "shares" not in reason.split(":")[0]
        assert all(r == reason for r in result.reasons)

    def test_registration_prefers_points_spread_over_the_image(self):
        # Two views see as many points; one has them all in a corner: the other scores higher.
        state = calibrated._State([(np.array([0, 1]), np.array([[10.0 + k, 10.0], [20.0 * (k % 30) + 5, 15.0 * (k // 30) + 5]]))
                                   for k in range(300)], [K800, K800])
        usable = state.obs_view >= 0
        scores = calibrated._visibility_scores(state, usable)
        assert scores[1] > 2 * scores[0]


# ---------------------------------------------------------------------------------------------
# Real photos: Middlebury dinoSparseRing, in tests/pipelines/reconstruction/test_reconstruction_ring.py


def _jpeg_with_focal_35mm(f35: int, order: str = "<") -> bytes:
    """A JPEG's first segments: SOI and an APP1 EXIF block whose EXIF IFD states
    FocalLengthIn35mmFilm (tag 0xA405, SHORT) = f35 (no image data: only the EXIF is read)."""
    mark = b"II" if order == "<" else b"MM"
    tiff = mark + struct.pack(order + "HI", 42, 8)
    ifd0 = struct.pack(order + "H", 1) + struct.pack(order + "HHII", 0x8769, 4, 1, 26) + struct.pack(order + "I", 0)
    exif = struct.pack(order + "H", 1) + struct.pack(order + "HHI", 0xA405, 3, 1) + struct.pack(order + "HH", f35, 0) \
        + struct.pack(order + "I", 0)
    body = b"Exif\x00\x00" + tiff + ifd0 + exif
    return b"\xff\xd8" + b"\xff\xe1" + struct.pack(">H", len(body) + 2) + body + b"\xff\xda\x00\x02"


class TestExifFocal:
    @pytest.mark.parametrize("order", ["<", ">"])
    def test_the_35mm_equivalent_gives_the_prior_in_pixels(self, order):
        # 36 mm equivalent on a 3000 px wide photo: 3000 px.
        assert features.exif_focal_px(_jpeg_with_focal_35mm(36, order), (3000, 2000)) == pytest.approx(3000.0)
        assert features.exif_focal_px(_jpeg_with_focal_35mm(0, order), (3000, 2000)) is None

    def test_a_prior_beyond_the_options_limit_is_not_taken(self):
        """The job's EXIF prior becomes its focal_prior_px, which the options (and the verifier
        reading them) hold to run_control.FOCAL_PRIOR_LIMIT: a 9,999 mm equivalent on a photo
        50,000 px wide states 1.39e7 px, and is ignored rather than written into a document the
        verifier would refuse."""
        import base64

        from geocert.formulations.reconstruction.run_control import FOCAL_PRIOR_LIMIT
        from geocert.kinds.reconstruction import _exif_focal_prior

        def images(f35):
            return [{"content": base64.b64encode(_jpeg_with_focal_35mm(f35)).decode()}] * 3

        assert _exif_focal_prior(images(36), [(3000, 2000)] * 3) == {"focal_px": pytest.approx(3000.0), "images": 3}
        assert features.exif_focal_px(_jpeg_with_focal_35mm(9999), (50_000, 100)) > FOCAL_PRIOR_LIMIT
        assert _exif_focal_prior(images(9999), [(50_000, 100)] * 3) is None
        assert _exif_focal_prior(images(7000), [(50_000, 100)] * 3)["focal_px"] <= FOCAL_PRIOR_LIMIT

    def test_no_exif_no_prior(self):
        assert features.exif_focal_px(b"\xff\xd8\xff\xda\x00\x02", (640, 480)) is None
        assert features.exif_focal_px(b"\x89PNG\r\n\x1a\n", (640, 480)) is None
