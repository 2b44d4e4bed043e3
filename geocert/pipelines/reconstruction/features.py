"""Tracks from photos: the image stage of the reconstruction pipeline (issue 14, stage 1).

Per image: SIFT keypoints and descriptors (OpenCV's ``cv2.SIFT_create``, Lowe 2004); when an
image has more than ``max_features`` keypoints, the largest-scale ones are kept (see
``select_keypoints``). Per pair of
images: each descriptor's two nearest neighbours in the other image; a match is kept when the
nearest is clearly nearer than the second (Lowe's ratio test) and, with ``mutual``, when the two
features are each other's nearest neighbour. The kept matches are verified geometrically: a
fundamental matrix is fitted by RANSAC (OpenCV's USAC MAGSAC++), and a pair whose inliers number
fewer than ``min_inliers`` contributes nothing (two views of a scene share a fundamental matrix;
chance matches do not). A pair of few matches gets no more trials than a verified pair, at least
``min_inliers`` of them inliers, would need (``ransac_trials``).

Which pairs are matched (``pairs``), chosen from the images, never from their order unless asked:
"exhaustive" every pair; "retrieval" each image with the ``retrieval_neighbours`` images most
alike it by a bag of visual words (a vocabulary of ``vocabulary_size`` words clustered from the
images' own descriptors, tf-idf weighted histograms compared by their cosine: Sivic and
Zisserman 2003, Nistér and Stewénius 2006; COLMAP's vocabulary-tree matching does the same with
a vocabulary trained beforehand); "auto" (the default) exhaustive up to ``exhaustive_limit``
images and retrieval beyond. "sequential" (video, or photos known to be in order) matches each
image with its ``neighbour_window`` successors in the order given, the last wrapping round to the
first when ``ring`` is set.

Guided matching (off by default: ``guided_ratio`` 0): a verified pair with at least
``guided_min_inliers`` inliers is matched again among the feature pairs that lie within
``guided_threshold_px`` of each other's epipolar lines of its fundamental matrix, the ratio test
taken among those candidates only (so a looser ``guided_ratio`` than the unguided one can keep
matches whose descriptors are only somewhat distinctive: an untextured surface seen from 20
degrees apart). The guided matches are verified again by RANSAC and replace the pair's matches
when more of them are inliers. Pairs with fewer inliers are left alone: their fundamental matrix
is too loosely determined (or wrong) to guide anything.

Tracks: the verified inlier matches link features (view, keypoint) into groups, the connected
components of that graph. A group holding two different features of one view is inconsistent (one scene point
cannot appear twice in an image: some match in it is wrong, and which one is unknown), so it is
dropped whole, and counted. Kept tracks have at least ``min_track_length`` views.

Coordinates are pixels as OpenCV reports keypoints: origin top-left, x to the right, y down, the
top-left pixel's centre at (0, 0).
"""

from __future__ import annotations

import base64
import binascii
import contextlib
import math
import os
import struct
import threading
import time
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.linalg import blas
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from geocert.core import pieces
from geocert.core.bnb import asks_to_stop
from geocert.core.geometry import InputError
from geocert.pipelines.reconstruction.options import FeatureOptions  # noqa: F401 (declared with the options)

# Limits on one image. The encoded size bounds the work of decoding and the memory a request can
# claim; the side and pixel limits are read from the file's header before decoding (so an image
# that claims to be huge is refused without being decompressed).
MAX_ENCODED_BYTES = 20_000_000
MAX_IMAGE_SIDE = 8192
MAX_IMAGE_PIXELS = 25_000_000
MIN_IMAGE_SIDE = 16


@dataclass
class ImageTracks:
    tracks: list[tuple[np.ndarray, np.ndarray]]  # (views int array, points (n, 2) float64 pixels)
    image_sizes: list[tuple[int, int]]  # (width, height) per image
    stats: dict = field(default_factory=dict)
    # "ok", "cancelled" (the callback asked to stop; tracks then empty) or "time_limit" (stopped at
    # options.time_limit_s: the tracks of the images and pairs done by then)
    status: str = "ok"


# ---------------------------------------------------------------------------------------------
# Decoding


def _png_size(data: bytes) -> tuple[int, int] | None:
    if data[:8] != b"\x89PNG\r\n\x1a\n" or len(data) < 24 or data[12:16] != b"IHDR":
        return None
    w, h = struct.unpack(">II", data[16:24])
    return int(w), int(h)


_SOF_MARKERS = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


def _jpeg_size(data: bytes) -> tuple[int, int] | None:
    """The frame size from a JPEG's start-of-frame segment (walking the segments from the top)."""
    if data[:2] != b"\xff\xd8":
        return None
    i = 2
    while i + 4 <= len(data):
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:  # segments without a length
            i += 2
            continue
        (length,) = struct.unpack(">H", data[i + 2:i + 4])
        if marker in _SOF_MARKERS:
            if i + 9 > len(data):
                return None
            h, w = struct.unpack(">HH", data[i + 5:i + 9])
            return int(w), int(h)
        if marker == 0xDA:  # start of scan before any frame header
            return None
        i += 2 + length
    return None


def _exif_entries(tiff: bytes, offset: int, order: str) -> dict[int, tuple[int, int, bytes]]:
    """One IFD's entries: tag -> (type, count, the 4 value-or-offset bytes)."""
    if offset + 2 > len(tiff):
        return {}
    (n,) = struct.unpack(order + "H", tiff[offset:offset + 2])
    entries = {}
    for k in range(min(n, 512)):
        at = offset + 2 + 12 * k
        if at + 12 > len(tiff):
            break
        tag, kind, count = struct.unpack(order + "HHI", tiff[at:at + 8])
        entries[tag] = (kind, count, tiff[at + 8:at + 12])
    return entries


def exif_focal_px(data: bytes, size: tuple[int, int]) -> float | None:
    """The focal length in pixels a JPEG's EXIF states, or None: its 35 mm equivalent
    (FocalLengthIn35mmFilm) times the larger image side over 36 mm. A prior, not a fact (a crop,
    a resize or a converter can make it wrong): the reconstruction refines it."""
    if data[:2] != b"\xff\xd8":
        return None
    i = 2
    while i + 4 <= len(data) and data[i] == 0xFF:
        marker = data[i + 1]
        (length,) = struct.unpack(">H", data[i + 2:i + 4])
        if marker == 0xE1 and data[i + 4:i + 10] == b"Exif\x00\x00":
            tiff = data[i + 10:i + 2 + length]
            order = {b"II": "<", b"MM": ">"}.get(tiff[:2])
            if order is None or len(tiff) < 8:
                return None
            (first,) = struct.unpack(order + "I", tiff[4:8])
            pointer = _exif_entries(tiff, first, order).get(0x8769)
            if pointer is None:
                return None
            (exif,) = struct.unpack(order + "I", pointer[2])
            entry = _exif_entries(tiff, exif, order).get(0xA405)
            if entry is None or entry[0] != 3:
                return None
            (f35,) = struct.unpack(order + "H", entry[2][:2])
            return float(f35) * max(size) / 36.0 if 0 < f35 < 10_000 else None
        if marker == 0xDA:
            return None
        i += 2 + length
    return None


# Deflate (PNG's compression) never packs more than 1032 bytes into one: a PNG whose compressed
# data is smaller than its pixels over that cannot hold them. A Huffman-coded JPEG spends at least
# a bit on each 8x8 block's DC coefficient. Decoders fill what is missing (a 400-byte JPEG whose
# header claims 5000x5000 decodes to 25 MB of grey), so such images are refused from their sizes.
_DEFLATE_MAX_RATIO = 1032
_PNG_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}
_ARITHMETIC_SOF = {0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


def _png_fills(data: bytes, w: int, h: int) -> bool:
    """Whether the PNG's chunks are whole, end with IEND, and hold enough compressed data for its pixels."""
    depth, colour = data[24], data[25]
    raw = h * (1 + -(-w * _PNG_CHANNELS.get(colour, 4) * depth // 8))  # bytes a row, plus its filter byte
    i, compressed = 8, 0
    while i + 12 <= len(data):
        (length,) = struct.unpack(">I", data[i:i + 4])
        kind = data[i + 4:i + 8]
        if i + 12 + length > len(data):
            return False
        if kind == b"IDAT":
            compressed += length
        if kind == b"IEND":
            return compressed * _DEFLATE_MAX_RATIO >= raw
        i += 12 + length
    return False


def _jpeg_fills(data: bytes, w: int, h: int) -> bool:
    """Whether the JPEG's segments lead to a scan, an end-of-image marker follows it, and at least
    a bit per 8x8 block lies between them (Huffman coding; arithmetic coding: the marker only)."""
    i, frame = 2, None
    while i + 4 <= len(data):
        if data[i] != 0xFF:
            return False
        marker = data[i + 1]
        if marker == 0xFF or marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:
            i += 1 if marker == 0xFF else 2
            continue
        if marker in _SOF_MARKERS and frame is None:
            frame = marker
        if marker == 0xDA:
            end = data.rfind(b"\xff\xd9")
            if frame is None or end <= i:
                return False
            return frame in _ARITHMETIC_SOF or 8 * (end - i) >= -(-w // 8) * -(-h // 8)
        (length,) = struct.unpack(">H", data[i + 2:i + 4])
        i += 2 + length
    return False


def image_header(content_b64: str, field: str) -> tuple[int, int, bytes]:
    """A base64 PNG or JPEG's width, height and bytes, read from its header without decoding its
    pixels (what the API checks of a photo: ``decode_image`` starts here).

    Refused with ``InputError(field, reason)``: content that is not a string, not base64, empty,
    not a PNG or JPEG, larger than the limits above (encoded bytes, sides, pixels), smaller than
    ``MIN_IMAGE_SIDE`` on a side, or whose data cannot fill the size its header declares (truncated).
    """
    if not isinstance(content_b64, str):
        raise InputError(field, "an image's content must be a base64 string (PNG or JPEG)")
    text = content_b64.strip()
    if text.startswith("data:"):
        head, sep, text = text.partition(",")
        if not sep or ";base64" not in head:
            raise InputError(field, "a data URL must be base64 encoded (data:image/png;base64,...)")
    text = "".join(text.split())  # line breaks are common in base64 text
    if not text:
        raise InputError(field, "the image is empty")
    if len(text) > (MAX_ENCODED_BYTES * 4) // 3 + 4:
        raise InputError(field, f"the image is larger than {MAX_ENCODED_BYTES} bytes")
    try:
        data = base64.b64decode(text, validate=True)
    except (binascii.Error, ValueError):
        raise InputError(field, "the content is not valid base64") from None
    if not data:
        raise InputError(field, "the image is empty")
    png = _png_size(data)
    size = png or _jpeg_size(data)
    if size is None:
        raise InputError(field, "the content is not a PNG or JPEG image (or its header is damaged)")
    w, h = size
    if w > MAX_IMAGE_SIDE or h > MAX_IMAGE_SIDE or w * h > MAX_IMAGE_PIXELS:
        raise InputError(field, f"the image is {w}x{h}; the limits are {MAX_IMAGE_SIDE} pixels a side "
                                f"and {MAX_IMAGE_PIXELS} pixels in all")
    if w < MIN_IMAGE_SIDE or h < MIN_IMAGE_SIDE:
        raise InputError(field, f"the image is {w}x{h}; at least {MIN_IMAGE_SIDE} pixels a side are needed")
    if not (_png_fills(data, w, h) if png else _jpeg_fills(data, w, h)):
        raise InputError(field, f"the image could not be decoded: its data ({len(data)} bytes) cannot fill the "
                                f"{w}x{h} pixels its header declares (truncated or corrupt)")
    return w, h, data


def decode_image(content_b64: str, field: str) -> np.ndarray:
    """A base64 PNG or JPEG (optionally a ``data:image/...;base64,`` URL) as a grayscale uint8
    array, refused as ``image_header`` refuses, or when OpenCV cannot decode it."""
    w, h, data = image_header(content_b64, field)
    image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_GRAYSCALE)
    if image is None or image.size == 0:
        raise InputError(field, "the image could not be decoded (truncated or corrupt)")
    if image.shape != (h, w):
        raise InputError(field, f"the decoded image is {image.shape[1]}x{image.shape[0]}, "
                                f"its header says {w}x{h}")
    return np.ascontiguousarray(image)


# ---------------------------------------------------------------------------------------------
# Tracks


PAIR_CHOICES = ("auto", "exhaustive", "retrieval", "sequential")


def candidate_pairs(n: int, options: FeatureOptions, descriptors: list[np.ndarray] | None = None,
                    seed: int = 0) -> tuple[list[tuple[int, int]], str]:
    """The image pairs to match and the rule that chose them (see the module docstring);
    ``descriptors`` (per image) are needed for retrieval."""
    rule = options.pairs
    if rule == "auto":
        rule = "exhaustive" if n <= options.exhaustive_limit or descriptors is None else "retrieval"
    if rule == "exhaustive" or (rule == "retrieval" and n <= options.retrieval_neighbours + 1):
        return [(i, j) for i in range(n) for j in range(i + 1, n)], "exhaustive"
    if rule == "retrieval":
        if descriptors is None:
            raise ValueError("retrieval needs the images' descriptors")
        similar = retrieval_neighbours(descriptors, options.retrieval_neighbours, options.vocabulary_size, seed)
        return sorted({(min(i, j), max(i, j)) for i, row in enumerate(similar) for j in row}), "retrieval"
    pairs = set()
    for i in range(n):
        for step in range(1, options.neighbour_window + 1):
            j = i + step
            if j >= n:
                if not options.ring:
                    break
                j -= n
            if j != i:
                pairs.add((min(i, j), max(i, j)))
    return sorted(pairs), "sequential"


def word_histograms(descriptors: list[np.ndarray], vocabulary_size: int, seed: int = 0,
                    sample: int = 20_000, iterations: int = 2) -> np.ndarray:
    """(n, words) tf-idf bag-of-words vectors, L2-normalised: a vocabulary by k-means (OpenCV's,
    k-means++ seeded) on at most ``sample`` of the images' RootSIFT descriptors, each descriptor
    its nearest word, each word weighted by log(n / images holding it)."""
    root = [np.sqrt(d / np.maximum(d.sum(axis=1, keepdims=True), 1e-12)).astype(np.float32) if len(d) else
            np.zeros((0, 128), np.float32) for d in descriptors]
    every = np.concatenate(root) if root else np.zeros((0, 128), np.float32)
    n = len(descriptors)
    words = int(min(vocabulary_size, max(1, len(every) // 4)))
    if len(every) == 0:
        return np.zeros((n, 1))
    rng = np.random.default_rng(seed)
    pick = every if len(every) <= sample else every[rng.choice(len(every), sample, replace=False)]
    cv2.setRNGSeed(seed)
    _, _, centres = cv2.kmeans(pick, words, None, (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, iterations, 1e-3),
                               1, cv2.KMEANS_PP_CENTERS)
    counts = np.zeros((n, words))
    for i, d in enumerate(root):
        if len(d):
            nearest = np.argmin((centres * centres).sum(1)[None, :] - 2.0 * d @ centres.T, axis=1)
            counts[i] = np.bincount(nearest, minlength=words)
    idf = np.log(n / np.maximum((counts > 0).sum(axis=0), 1))
    vectors = counts / np.maximum(counts.sum(axis=1, keepdims=True), 1) * idf
    return vectors / np.maximum(np.linalg.norm(vectors, axis=1, keepdims=True), 1e-12)


def retrieval_neighbours(descriptors: list[np.ndarray], k: int, vocabulary_size: int, seed: int = 0) -> list[list[int]]:
    """Per image, the ``k`` other images whose word histograms are most alike (cosine)."""
    vectors = word_histograms(descriptors, vocabulary_size, seed)
    similarity = vectors @ vectors.T
    np.fill_diagonal(similarity, -np.inf)
    k = min(k, len(descriptors) - 1)
    return [list(map(int, np.argsort(-row, kind="stable")[:k])) for row in similarity]


def build_tracks(pair_matches: dict[tuple[int, int], np.ndarray], features_per_view: list[int],
                 min_track_length: int = 2) -> tuple[list[list[tuple[int, int]]], dict]:
    """The connected groups of features (view, keypoint) linked by ``pair_matches[(i, j)]`` ((m, 2)
    rows of keypoint indices in view i and view j). Returns the kept tracks (each a list of (view,
    keypoint) sorted by view, the tracks ordered by their first member) and counts: groups built,
    dropped as inconsistent, dropped as short, kept."""
    # scipy's connected components over the features' sparse graph: one pass in C, where a
    # union-find in Python took a loop step per match.
    offsets = np.concatenate([[0], np.cumsum(features_per_view)]).astype(np.int64)
    ends = [(offsets[i] + m[:, 0], offsets[j] + m[:, 1]) for (i, j), matches in pair_matches.items()
            for m in [np.asarray(matches, dtype=np.int64).reshape(-1, 2)]]
    u = np.concatenate([e[0] for e in ends]) if ends else np.zeros(0, dtype=np.int64)
    v = np.concatenate([e[1] for e in ends]) if ends else np.zeros(0, dtype=np.int64)
    counts = {"tracks_built": 0, "dropped_inconsistent": 0, "dropped_short": 0, "tracks_kept": 0}
    if not len(u):
        return [], counts
    n = int(offsets[-1])
    graph = coo_matrix((np.ones(len(u), dtype=np.int8), (u, v)), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    linked = np.unique(np.concatenate([u, v]))  # sorted: by view, then keypoint
    order = np.argsort(labels[linked], kind="stable")  # a group's members stay sorted
    nodes = linked[order]
    group = labels[nodes]
    views = np.searchsorted(offsets, nodes, side="right") - 1
    starts = np.flatnonzero(np.r_[True, group[1:] != group[:-1]])
    sizes = np.diff(np.r_[starts, len(nodes)])
    # Two members of one group in one view sit side by side (members are sorted by view).
    repeated = (views[1:] == views[:-1]) & (group[1:] == group[:-1])
    inconsistent = np.add.reduceat(np.r_[repeated, False].astype(np.int64), starts) > 0
    short = ~inconsistent & (sizes < min_track_length)
    keep = ~inconsistent & ~short
    keypoints = nodes - offsets[views]
    kept = [list(zip(views[s:s + k].tolist(), keypoints[s:s + k].tolist()))
            for s, k in zip(starts[keep].tolist(), sizes[keep].tolist())]
    kept.sort(key=lambda t: t[0])
    counts.update(tracks_built=len(starts), dropped_inconsistent=int(inconsistent.sum()),
                  dropped_short=int(short.sum()), tracks_kept=len(kept))
    return kept, counts


# Distance matrices of at least this many entries have their mutual test read from a product of
# the candidate columns' descriptors with every row's (a few percent of the pair's product) rather
# than gathered from the matrix: a column of a large matrix is read an entry per cache line. The
# same numbers either way; which is cheaper depends on the caches. On kittiTurn's photos (about
# 3,000 keypoints) the product is cheaper from 2,000 x 2,000 up, the gather below 1,400 x 1,400
# (templeSparseRing's size): bench/results/reconstruction_vs_colmap.md, "the features and matches
# stage profiled again".
MUTUAL_BY_PRODUCT = 3_000_000


def _match(desc_a: np.ndarray, desc_b: np.ndarray, options: FeatureOptions) -> np.ndarray:
    """Ratio-test (and mutual) matches as (m, 2) keypoint indices.

    Squared descriptor distances come from one matrix product (|a|^2 + |b|^2 - 2 a.b), which gives
    both directions' nearest neighbours at once (brute force, exact as cv2.BFMatcher with NORM_L2,
    which was 5 times slower here)."""
    if len(desc_a) < 2 or len(desc_b) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    # A row's nearest and second-nearest columns do not depend on its own |a|^2: the matrix holds
    # |b|^2 - 2 a.b, and |a|^2 is added to the two distances the ratio test reads (and to the
    # columns the mutual test reads), two passes over the matrix fewer. Every term is an integer
    # below 2^24 (see _squared_distances), so each distance is the same number either way.
    a, b = desc_a.astype(np.float32, copy=False), desc_b.astype(np.float32, copy=False)
    minus_2b = -2.0 * b
    row_offset = np.einsum("ij,ij->i", a, a)
    column_distances = None
    if len(a) * len(b) >= MUTUAL_BY_PRODUCT:
        def column_distances(columns: np.ndarray) -> np.ndarray:
            # (columns, rows): the columns' squared distances to every row less the column's |b|^2
            # (a constant down a column: the nearest row is the same)
            read = minus_2b[columns] @ a.T
            read += row_offset[None, :]
            return read
    return _ratio_matches(_partial_distances(a, minus_2b, np.einsum("ij,ij->i", b, b)), options.ratio,
                          options.mutual, row_offset, column_distances)


def _partial_distances(a: np.ndarray, minus_2b: np.ndarray, b_squared: np.ndarray) -> np.ndarray:
    """(n_a, n_b) float32, C order: |b|^2 - 2 a.b, the squared distances less each row's |a|^2.

    One product accumulated onto the |b|^2 rows (BLAS's sgemm with beta 1) rather than a product
    then |b|^2 added: one pass over the matrix fewer. The sums are integers below 2^24 in any order
    (see _squared_distances): the same numbers as the product and the addition."""
    # Fortran's (n_b, n_a) is C's (n_a, n_b): BLAS fills it as op(A) op(B) with op(A) = minus_2b and
    # op(B) = a^T, both read in place (their transposes are Fortran-ordered).
    out = np.empty((len(minus_2b), len(a)), dtype=np.float32, order="F")
    out[...] = b_squared[:, None]
    out = blas.sgemm(1.0, minus_2b.T, a.T, beta=1.0, c=out, trans_a=1, overwrite_c=1)
    return out.T


def _squared_distances(desc_a: np.ndarray, desc_b: np.ndarray) -> np.ndarray:
    # In place on the product (one array the size of d2, not four). SIFT's descriptors are
    # integers (OpenCV's at most 255 an entry), so every term is an integer below 2^24: exact in
    # float32 whatever the order of the sums.
    a, b = desc_a.astype(np.float32, copy=False), desc_b.astype(np.float32, copy=False)
    d2 = a @ (-2.0 * b).T
    d2 += np.einsum("ij,ij->i", a, a)[:, None]
    d2 += np.einsum("ij,ij->i", b, b)[None, :]
    return np.maximum(d2, 0.0, out=d2)


def _ratio_matches(d2: np.ndarray, ratio: float, mutual: bool, row_offset: np.ndarray | None = None,
                   column_distances=None) -> np.ndarray:
    """Each row's nearest column, kept when nearer than ``ratio`` times the second-nearest (a
    single column passes; an infinite distance, a pair not allowed, never does) and, with
    ``mutual``, when the two are each other's nearest. ``row_offset``: when given, the squared
    distances are ``d2 + row_offset[:, None]`` (d2 then a row's distances less a constant).
    ``column_distances(columns)``: when given, the mutual test reads the columns' distances from it,
    (columns, rows), each column's less a constant, instead of from d2 (see MUTUAL_BY_PRODUCT)."""
    # Minima and argmins along rows, and minima along columns, are single passes over d2 (an
    # argpartition, or an argmin down the columns, costs as much as the distances themselves).
    rows = np.arange(d2.shape[0])
    nearest = np.argmin(d2, axis=1) if d2.shape[1] else np.zeros(len(rows), dtype=np.int64)
    if d2.shape[1] >= 2:
        d_first = d2[rows, nearest]
        d2[rows, nearest] = np.inf  # the second nearest is the nearest of the others
        d_second = d2.min(axis=1)
        d2[rows, nearest] = d_first
    else:
        d_first, d_second = d2[:, 0], np.full(len(rows), np.inf)
    if row_offset is not None:
        d_first = np.maximum(d_first + row_offset, 0.0)
        d_second = np.maximum(d_second + row_offset, 0.0)
    keep = np.isfinite(d_first) & (d_first < (ratio ** 2) * d_second)
    if mutual and keep.any():
        # Each other's nearest: the row is its column's nearest, the first of equals (np.argmin's
        # choice down the column). Only the columns of rows passing the ratio test are read (a few
        # percent of them on real photos: a pass over d2's columns costs as much as the product).
        candidates = np.flatnonzero(keep)
        columns, which = np.unique(nearest[candidates], return_inverse=True)
        if column_distances is not None:
            first_row = np.argmin(column_distances(columns), axis=1)
        else:
            read = d2[:, columns]
            if row_offset is not None:
                read += row_offset[:, None]
            first_row = np.argmin(read, axis=0)
        keep[candidates] = first_row[which.ravel()] == candidates
    return np.c_[rows[keep], nearest[keep]].astype(np.int64)


# MAGSAC++'s minimal sample for a fundamental matrix (OpenCV's USAC: the seven-point solver); the
# factor on the trials RANSAC's stopping rule asks for (see ransac_trials); and the fewest trials a
# pair gets (COLMAP's RANSAC min_num_trials).
SAMPLE_SIZE = 7
TRIALS_MULTIPLIER = 5
MIN_TRIALS = 100


def ransac_trials(matches: int, options: FeatureOptions) -> int:
    """The trials RANSAC runs on a pair of ``matches`` putative matches: ``ransac_max_iters``, or
    fewer when ``min_inliers`` inliers among the matches would need fewer. RANSAC's stopping rule,
    log(1 - confidence) / log(1 - w^7) trials at inlier ratio w (the rule MAGSAC++ applies once it
    holds a model), taken at the least ratio a verified pair can have and before the first trial,
    times TRIALS_MULTIPLIER, at least MIN_TRIALS. The multiplier is there because a sample free of
    outliers does not always give a model every inlier fits within the threshold (noise). On 1,500
    synthetic pairs of 15 to 17 true matches among 20 to 30 (0.3 px noise), against 5,000 trials:
    the rule's own count lost 70 of the pairs that verify, three times it (COLMAP's
    dyn_num_trials_multiplier) 5, five times it none (bench/results/reconstruction_vs_colmap.md,
    "RANSAC's trials bounded by the inliers a pair needs"). Under the defaults only pairs of at
    most 30 matches are capped: mostly pairs that verify nothing, which ran to ``ransac_max_iters``."""
    ratio = min(options.min_inliers, matches) / max(matches, 1)
    # the log of a sample's chance to hold an outlier (0 when no ratio is least: min_inliers 0)
    miss = math.log1p(-(ratio ** SAMPLE_SIZE)) if ratio < 1.0 else -math.inf
    if miss == 0.0 or options.ransac_confidence >= 1.0:
        needed = options.ransac_max_iters
    else:
        needed = math.ceil(TRIALS_MULTIPLIER * math.log1p(-options.ransac_confidence) / miss)
    return int(min(options.ransac_max_iters, max(MIN_TRIALS, needed)))


def fit_fundamental(points_a: np.ndarray, points_b: np.ndarray,
                    options: FeatureOptions) -> tuple[np.ndarray | None, np.ndarray]:
    """A RANSAC fundamental matrix (x_b^T F x_a = 0) and its inlier mask (None and all False when
    none is found), from at most ``ransac_trials`` trials."""
    none = np.zeros(len(points_a), dtype=bool)
    if len(points_a) < max(8, options.min_inliers):
        return None, none
    F, mask = cv2.findFundamentalMat(points_a, points_b, cv2.USAC_MAGSAC, options.ransac_threshold_px,
                                     options.ransac_confidence, ransac_trials(len(points_a), options))
    if F is None or mask is None or F.shape != (3, 3):
        return None, none
    return F, mask.ravel().astype(bool)


def epipolar_distances(F: np.ndarray, points_a: np.ndarray, points_b: np.ndarray) -> np.ndarray:
    """(n_a, n_b): for every point of a and point of b, the larger of the two pixel distances, of
    b's point to a's epipolar line F x_a and of a's point to b's line F^T x_b."""
    ha = np.c_[points_a, np.ones(len(points_a))]
    hb = np.c_[points_b, np.ones(len(points_b))]
    la, lb = ha @ F.T, hb @ F  # a's lines in b, b's lines in a
    algebraic = np.abs(ha @ lb.T)  # |x_b^T F x_a|
    norm_a = np.maximum(np.hypot(la[:, 0], la[:, 1]), 1e-300)
    norm_b = np.maximum(np.hypot(lb[:, 0], lb[:, 1]), 1e-300)
    return np.maximum(algebraic / norm_a[:, None], algebraic / norm_b[None, :])


def guided_matches(keypoints_a: np.ndarray, desc_a: np.ndarray, keypoints_b: np.ndarray, desc_b: np.ndarray,
                   F: np.ndarray, options: FeatureOptions) -> np.ndarray:
    """Matches (m, 2) among the feature pairs within the guided threshold of each other's epipolar
    lines: each feature of a with its nearest allowed descriptor of b, kept when it is nearer than
    ``guided_ratio`` times the second-nearest allowed one (a single candidate passes) and, with
    ``mutual``, when the two are each other's nearest allowed feature."""
    if len(desc_a) == 0 or len(desc_b) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    threshold = options.guided_threshold_px or options.ransac_threshold_px
    allowed = epipolar_distances(F, keypoints_a, keypoints_b) <= threshold
    d2 = np.where(allowed, _squared_distances(desc_a, desc_b), np.inf)
    return _ratio_matches(d2, options.guided_ratio, options.mutual)


def match_pair(keypoints_a: np.ndarray, desc_a: np.ndarray, keypoints_b: np.ndarray, desc_b: np.ndarray,
               options: FeatureOptions) -> tuple[np.ndarray, dict] | None:
    """One pair's verified matches ((m, 2) keypoint indices) and figures, or None when fewer than
    ``min_inliers`` fit one fundamental matrix. A pure function of the pair's features: the pairs
    are independent work items (a runner may spread them over workers)."""
    rows = _match(desc_a, desc_b, options)
    F, inliers = fit_fundamental(keypoints_a[rows[:, 0]], keypoints_b[rows[:, 1]], options)
    if inliers.sum() < options.min_inliers:
        return None
    figures = {"matches": len(rows), "inliers": int(inliers.sum())}
    kept = rows[inliers]
    if options.guided_ratio > 0 and inliers.sum() >= options.guided_min_inliers:
        guided = guided_matches(keypoints_a, desc_a, keypoints_b, desc_b, F, options)
        _, again = fit_fundamental(keypoints_a[guided[:, 0]], keypoints_b[guided[:, 1]], options)
        figures["guided"] = int(again.sum())
        if again.sum() > inliers.sum():
            kept = guided[again]
            figures["inliers"] = int(again.sum())
    return kept, figures


def select_keypoints(keypoints, max_features: int) -> list:
    """At most ``max_features`` of the keypoints (0: all), the largest-scale first (the strongest
    response first among equal scales), in the order detected.

    OpenCV's own limit (``SIFT_create(nfeatures=...)``) keeps the strongest responses, which on a
    high-resolution photo are mostly at the finest scales: foliage, gravel, sensor and JPEG noise,
    which the next photo, taken from elsewhere, does not repeat. On Sceaux Castle's 6 Mpx photos
    the 4000 strongest of a close-up under foliage (94,000 detected) matched no other photo
    (10-12 chance inliers), where its 4000 largest-scale keypoints have 312 inliers with the next
    photo. COLMAP's SIFT keeps the coarsest octaves the same way (dropping the finest first).
    Images with fewer keypoints than the limit keep them all, as before."""
    return [keypoints[i] for i in _selected(keypoints, max_features)]


def _selected(keypoints, max_features: int) -> np.ndarray:
    """select_keypoints's choice as indices into ``keypoints``, ascending."""
    if not max_features or len(keypoints) <= max_features:
        return np.arange(len(keypoints))
    size = np.array([k.size for k in keypoints])
    response = np.array([k.response for k in keypoints])
    return np.sort(np.lexsort((-response, -size))[:max_features])


# Images of at most this many pixels get their keypoints and descriptors from one SIFT pass
# (detectAndCompute: one scale space) rather than detect, then compute on the keypoints kept (two):
# OpenCV's compute builds its scale space from the keypoints' lowest octave, the doubled image's
# (-1) as detect's whenever one of them is there, so each descriptor is the same either way (the
# descriptors of the keypoints select_keypoints drops are computed for nothing, which is why large
# images, with tens of thousands of keypoints, keep the two passes).
ONE_PASS_PIXELS = 2_000_000


def sift_features(sift, image: np.ndarray, max_features: int) -> tuple[list, np.ndarray | None]:
    """The keypoints select_keypoints keeps of those ``sift`` detects in the grayscale uint8
    image, and their descriptors: ``sift.compute(image, select_keypoints(sift.detect(image,
    None), max_features))``, from one pass where that gives the same (ONE_PASS_PIXELS)."""
    if image.size > ONE_PASS_PIXELS:
        return sift.compute(image, select_keypoints(sift.detect(image, None), max_features))
    found, described = sift.detectAndCompute(image, None)
    kept = _selected(found, max_features)
    keypoints = [found[i] for i in kept]
    if described is not None and len(kept) and min(map(_octave, keypoints)) < 0:
        return keypoints, described[kept]
    return sift.compute(image, keypoints)  # compute's scale space starts at another octave than detect's


def _octave(keypoint) -> int:
    """The octave OpenCV's SIFT packs in a keypoint's low byte (signed: -1 the doubled image)."""
    octave = keypoint.octave & 255
    return octave - 256 if octave >= 128 else octave


# Images read, and pairs matched, at once: OpenCV's SIFT and RANSAC and numpy's products release the
# interpreter's lock, so a worker uses two cores on them, as the camera stage does
# (structure.CAMERA_THREADS). Each item's result is the same as alone (MAGSAC++ seeds its own
# generator per call), and results are taken in the items' order.
FEATURE_THREADS = 2


def in_order_threads(function, items: list, stop) -> list | None:
    """``function(item)`` for the items, FEATURE_THREADS at a time (at most the processors), the
    results in the items' order: core.pieces.in_threads (``stop`` as it reads it)."""
    return pieces.in_threads(function, items, stop, FEATURE_THREADS)


# OpenCV's own threads (its parallel_for in SIFT's blurs, extrema and descriptors) are off while the
# stage's threads fill every processor: they only contend with the stage's other thread for the
# same cores and spin waiting for work (measured in bench/results/reconstruction_vs_colmap.md,
# "the features and matches stage profiled again"). What OpenCV computes does not depend on its
# thread count (SIFT sorts its keypoints before describing them). A process-wide setting: set by
# the first stage running and put back by the last (stages of one process may overlap in threads).
_OPENCV_LOCK = threading.Lock()
_opencv_stages = 0
_opencv_before = 1


def _processors() -> int:
    return os.cpu_count() or 1


@contextlib.contextmanager
def opencv_threads_off():
    """Within the block, OpenCV runs each call in its caller's thread when the stage's
    FEATURE_THREADS fill the processors (else its own threads are left as they are); the
    setting before is put back when the last such block in the process ends."""
    global _opencv_stages, _opencv_before
    if _processors() > FEATURE_THREADS:
        yield
        return
    with _OPENCV_LOCK:
        if _opencv_stages == 0:
            _opencv_before = cv2.getNumThreads()
            cv2.setNumThreads(1)
        _opencv_stages += 1
    try:
        yield
    finally:
        with _OPENCV_LOCK:
            _opencv_stages -= 1
            if _opencv_stages == 0:
                cv2.setNumThreads(_opencv_before)


_DETECTORS = threading.local()  # a detector per thread: OpenCV does not promise one is safe to share


@pieces.piece
def image_features(options: FeatureOptions, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One image's keypoints ((n, 2) pixels) and SIFT descriptors: a piece of the features stage
    (core.pieces), a pure function of the image and options."""
    settings = (options.contrast_threshold, options.edge_threshold)
    if getattr(_DETECTORS, "settings", None) != settings:
        # nfeatures 0: every keypoint detected, then select_keypoints keeps the largest-scale ones
        _DETECTORS.sift = cv2.SIFT_create(nfeatures=0, contrastThreshold=options.contrast_threshold,
                                          edgeThreshold=options.edge_threshold)
        _DETECTORS.settings = settings
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    kps, desc = sift_features(_DETECTORS.sift, np.ascontiguousarray(image, dtype=np.uint8), options.max_features)
    return (np.array([kp.pt for kp in kps], dtype=np.float64).reshape(-1, 2),
            desc if desc is not None else np.zeros((0, 128), np.float32))


@pieces.piece
def pair_matches(shared: tuple, pair: tuple[int, int]) -> tuple[np.ndarray, dict] | None:
    """One image pair's verified matches (match_pair): a piece of the matches stage, ``shared``
    the images' (keypoints, descriptors, options)."""
    keypoints, descriptors, options = shared
    i, j = pair
    return match_pair(keypoints[i], descriptors[i], keypoints[j], descriptors[j], options)


def tracks_from_images(images: list[np.ndarray], options: FeatureOptions | None = None,
                       callback=None) -> ImageTracks:
    """Features, verified matches and tracks for grayscale uint8 images (see the module docstring).

    ``callback(progress)`` gets {"stage": "features" | "matches", "done": k, "total": n} and may
    return True to stop (the result then has status "cancelled" and no tracks). Past
    ``options.time_limit_s`` the images not yet read and the pairs not yet matched are left out:
    status "time_limit", ``stats["stopped"]`` says where. OpenCV's own threads are off meanwhile
    when the stage's fill the processors (opencv_threads_off)."""
    with opencv_threads_off():
        return _tracks(images, options or FeatureOptions(), callback)


def _tracks(images: list[np.ndarray], options: FeatureOptions, callback) -> ImageTracks:
    """tracks_from_images's work."""
    sizes = [(int(im.shape[1]), int(im.shape[0])) for im in images]  # grayscale or BGR uint8
    timing: dict[str, float] = {}
    stats: dict = {"images": len(images), "time_s": timing}
    start = began = time.perf_counter()
    status = "ok"

    def over_time(where: str) -> bool:
        nonlocal status
        if time.perf_counter() - began <= options.time_limit_s:
            return False
        if status == "ok":
            status = "time_limit"
            stats["stopped"] = f"{where}, at options.features.time_limit_s ({options.time_limit_s:g} s)"
        return True

    def features_stop(k: int) -> bool | None:
        if asks_to_stop(callback, {"stage": "features", "done": k, "total": len(images)}):
            return None  # cancelled
        return over_time(f"features read of {k} of {len(images)} images")

    found = pieces.mapped(image_features, options, images, features_stop, in_order_threads)
    if found is None:
        return ImageTracks([], sizes, stats, "cancelled")
    keypoints, descriptors = [k for k, _ in found], [d for _, d in found]
    stats["features_per_image"] = [len(k) for k in keypoints] + [0] * (len(images) - len(keypoints))
    timing["features"] = time.perf_counter() - start

    start = time.perf_counter()
    # nothing matched once the time is up (choosing pairs by retrieval clusters descriptors)
    pairs, rule = ([], "none") if over_time("no image pairs matched") else \
        candidate_pairs(len(descriptors), options, descriptors)
    stats["candidate_pairs"] = len(pairs)
    stats["pairs_chosen_by"] = rule
    verified_matches: dict[tuple[int, int], np.ndarray] = {}
    verified: list[dict] = []

    def matches_stop(k: int) -> bool | None:
        if asks_to_stop(callback, {"stage": "matches", "done": k, "total": len(pairs)}):
            return None  # cancelled
        return over_time(f"{k} of {len(pairs)} image pairs matched")

    matched = pieces.mapped(pair_matches, (keypoints, descriptors, options), pairs, matches_stop, in_order_threads)
    if matched is None:
        return ImageTracks([], sizes, stats, "cancelled")
    for (i, j), found in zip(pairs, matched):
        if found is not None:
            verified_matches[(i, j)], figures = found
            verified.append({"views": [i, j], **figures})
    stats["verified_pairs"] = verified
    asks_to_stop(callback, {"stage": "matches", "done": len(pairs), "total": len(pairs)})
    timing["matches"] = time.perf_counter() - start

    start = time.perf_counter()
    groups, counts = build_tracks(verified_matches, stats["features_per_image"], options.min_track_length)
    stats.update(counts)
    tracks = []
    for members in groups:
        views = np.array([v for v, _ in members], dtype=np.int64)
        points = np.array([keypoints[v][f] for v, f in members], dtype=np.float64).reshape(-1, 2)
        tracks.append((views, points))
    timing["tracks"] = time.perf_counter() - start
    return ImageTracks(tracks, sizes, stats, status)
