"""Small projective-geometry helpers shared by the solvers and the input checks."""

from __future__ import annotations

import math

import numpy as np


class InputError(ValueError):
    """Bad problem data; ``field`` names where (a JSON-pointer-like path), the message says why."""

    def __init__(self, field: str, reason: str):
        super().__init__(f"{field}: {reason}")
        self.field = field
        self.reason = reason


# Largest magnitude of an observed coordinate (pixels, or the units of a map's points). Beyond it
# the products the relaxations are built from lose the digits a certificate needs; a job with
# such a coordinate is refused with the field and this limit named, rather than answered badly.
COORDINATE_LIMIT = 1e9

# The largest image side taken, in pixels: far above any camera's (the largest sensors are some
# 2e4 px a side, stitched gigapixel panoramas some 2e5). Beyond some 1e7 the default ranges'
# scale left the affine stage failing with a reason about the data ("chirality does not bound
# the plane at infinity", "no strictly quasi-affine plane") when the size was the cause.
MAX_IMAGE_SIDE_PX = 1e6

# The largest focal length, skew or principal point coordinate taken, in pixels (an intrinsics
# range's ends, a known K's entries): ten times the largest image side. A focal length of 1e7 px
# is a pixel of 0.02 arc seconds, finer than any telescope's (a 2e4 px sensor behind an 800 mm lens
# is some 2e5 px), and a principal point 1e7 px off is ten sides beyond the largest image taken.
# Between this and COORDINATE_LIMIT a range no image taken here can have was queued.
MAX_INTRINSIC_PX = 10 * MAX_IMAGE_SIDE_PX


def is_number(x) -> bool:
    """A finite JSON number: a float or an int (never a bool or a string)."""
    if type(x) is float:  # not bool, not str
        return math.isfinite(x)
    return type(x) is int and abs(x) < 2**1023


def number_array(value, field: str, what: str, ndim: int, limit: float | None = None) -> np.ndarray:
    """A JSON value of nested lists of numbers, taken strictly: no strings, no booleans, no
    non-finite values, exactly ``ndim`` levels, rows of one length; with ``limit``, every entry
    within +-limit. Raises InputError naming the first offending entry."""
    rows = _rows(value, field, what, ndim)
    # Rows of floats and ints only (the common case) are checked in bulk, by type here and by
    # value below (an int beyond 2**1023, which is_number refuses, sends every row to the slow
    # check); any other row, and any failure below, goes through the entry-by-entry check, which
    # names the first offending entry. (Integers took the slow path: 6 microseconds an entry.)
    slow = [(where, row) for where, row in rows if not NUMBER_TYPES.issuperset(map(type, row))]
    for where, row in slow:
        _check_entries(where, row, what, limit)
    try:
        array = np.array(value, dtype=float)
    except OverflowError:  # an int beyond any float
        for where, row in rows:
            _check_entries(where, row, what, limit)
        raise
    except ValueError as exc:  # ragged
        raise InputError(field, f"must be {what} (rows of one length)") from exc
    if array.ndim != ndim:
        raise InputError(field, f"must be {what}")
    magnitude = np.abs(array)
    if not (np.isfinite(array).all() and (limit is None or (magnitude <= limit).all())
            and (magnitude < 2.0 ** 1023).all()):
        for where, row in rows:
            _check_entries(where, row, what, limit)
    return array


NUMBER_TYPES = frozenset((float, int))  # exact types: a bool is neither


def _rows(value, field: str, what: str, ndim: int) -> list[tuple[str, list]]:
    """The innermost lists of a value of ``ndim`` levels, each with its field path."""
    if ndim == 1:
        if not isinstance(value, list):
            raise InputError(field, f"must be {what}")
        return [(field, value)]
    if not isinstance(value, list):
        raise InputError(field, f"must be {what}")
    rows = []
    for i, row in enumerate(value):
        rows.extend(_rows(row, f"{field}/{i}", what, ndim - 1))
    return rows


def _check_entries(where: str, row: list, what: str, limit: float | None) -> None:
    for j, x in enumerate(row):
        if not is_number(x):
            kind = "a string" if isinstance(x, str) else "a boolean" if isinstance(x, bool) else \
                "not finite" if isinstance(x, float) else f"a {type(x).__name__}"
            raise InputError(f"{where}/{j}", f"must be a finite number, got {kind}")
        if limit is not None and abs(x) > limit:
            raise InputError(f"{where}/{j}", f"magnitude {abs(x):g} exceeds the limit {limit:g} "
                                             "(rescale the coordinates, e.g. to pixels or metres)")


def normalised_cameras(cameras: np.ndarray) -> np.ndarray:
    """Cameras (k, 3, 4) each divided by a power of two near its largest entry, when that entry
    is far from 1 (beyond 2^+-64). A camera is defined up to a positive scale, and a power of two
    scales every product exactly, so residuals and depths keep their values to the last bit;
    only entries near the limits of floating point (1e300, 1e-300), whose squares overflow or
    vanish, are changed. Solvers and verifier read cameras through this."""
    cams = np.array(cameras, dtype=float)
    if cams.ndim != 3 or not len(cams) or not cams[0].size:
        far = range(len(cams))
    else:  # the cameras that may be far from 1 (a superset: zero, non-finite), found at once
        largest = np.abs(cams).max(axis=(1, 2))
        far = np.flatnonzero(~((largest > 2.0 ** -65) & (largest < 2.0 ** 64)))
    for cam in (cams[k] for k in far):
        largest = float(np.max(np.abs(cam)))
        if largest > 0 and np.isfinite(largest):
            exponent = math.frexp(largest)[1]
            if abs(exponent) > 64:  # np.ldexp scales in one step: 2^-exponent alone overflows for subnormal entries
                cam[...] = np.ldexp(cam, -exponent)
    return cams


def check_cameras(cameras: np.ndarray, field: str = "cameras") -> np.ndarray:
    """Return cameras as an (N, 3, 4) float array (normalised_cameras), or raise InputError
    naming the bad camera and the reason."""
    cams = np.asarray(cameras, dtype=float)
    if cams.ndim != 3 or cams.shape[1:] != (3, 4):
        raise InputError(field, f"expected a list of 3x4 matrices, got shape {list(cams.shape)}")
    if cams.shape[0] == 0:
        raise InputError(field, "at least one camera is required")
    finite = np.isfinite(cams).all(axis=(1, 2))
    if not finite.all():
        raise InputError(f"{field}/{int(np.argmin(finite))}", "contains a non-finite number")
    cams = normalised_cameras(cams)
    # Every camera's checks at once (one batched SVD: the same values as one camera's own), the
    # first camera failing one named, with the first of its checks it fails, in this order.
    zero = ~cams.any(axis=(1, 2))
    singular = np.linalg.svd(cams, compute_uv=False)
    deficient = singular[:, 2] <= 1e-12 * singular[:, 0]
    no_depth = (np.linalg.norm(cams[:, 2, :3], axis=1) == 0) & (cams[:, 2, 3] == 0)
    failing = zero | deficient | no_depth
    if failing.any():
        i = int(np.argmax(failing))
        if zero[i]:
            raise InputError(f"{field}/{i}", "camera matrix is zero")
        if deficient[i]:
            raise InputError(f"{field}/{i}", f"camera matrix is rank-deficient: its singular values "
                                             f"{singular[i].tolist()} have a ratio below 1e-12 (rank < 3)")
        raise InputError(f"{field}/{i}", "camera has a zero depth row")
    return cams


def fundamental_from_cameras(P1: np.ndarray, P2: np.ndarray) -> np.ndarray:
    """F with x2' F x1 = 0 for the two cameras (Hartley & Zisserman, eq. 9.1)."""
    _, _, vt = np.linalg.svd(P1)
    centre = vt[-1]
    epipole = P2 @ centre
    skew = np.array([[0, -epipole[2], epipole[1]], [epipole[2], 0, -epipole[0]], [-epipole[1], epipole[0], 0]])
    return skew @ P2 @ np.linalg.pinv(P1)


def reprojection_residuals(cameras: np.ndarray, X: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(k, 2) residuals of homogeneous X in cameras (k, 3, 4) against points (k, 2), in pixels."""
    proj = cameras @ X
    return proj[:, :2] / proj[:, 2:3] - points


def depths(cameras: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Third coordinate of P X, with X's sign fixed so that its last coordinate is not negative."""
    X = X if X[3] >= 0 else -X
    return cameras[:, 2, :] @ X


def norm_terms(residuals: np.ndarray, norm: str) -> np.ndarray:
    """Each observation's cost term, residuals (..., n, m) -> (..., n): norm_cost is their sum."""
    if norm == "L2L2":
        return (residuals * residuals).sum(axis=-1)
    return lengths(residuals) if norm == "L2L1" else np.abs(residuals).sum(axis=-1)


def cost_roundings(residuals: np.ndarray, rounding: np.ndarray, norm: str) -> np.ndarray:
    """How much a cost can change when each residual coordinate moves by its ``rounding`` bound,
    residuals and rounding (..., n, m) -> (...): the only slack beside the relative
    OBJECTIVE_TOLERANCE, tied to the data, not the document."""
    if norm == "L2L2":
        return np.sum(2 * np.abs(residuals) * rounding + rounding * rounding, axis=(-2, -1))
    if norm == "L2L1":
        return lengths(rounding).sum(axis=-1)
    return np.sum(rounding, axis=(-2, -1))


def cost_rounding(residuals: np.ndarray, rounding: np.ndarray, norm: str) -> float:
    """cost_roundings of one item."""
    return float(cost_roundings(residuals, rounding, norm))


def lengths(x: np.ndarray, axis: int = -1) -> np.ndarray:
    """np.linalg.norm(x, axis=axis) for real x (the same sums), without its argument handling:
    the hot paths call it on small arrays."""
    return np.sqrt((x * x).sum(axis=axis))


# Magnitudes whose squares (and sums of a few of them) neither underflow nor overflow; outside,
# a length is read at an exact power of two (square_safe_shift) so a world in a tiny or huge unit
# gets the same figures as in metres, scaled. Inside, the code paths are unchanged.
SQUARES_SAFE = (1e-150, 1e150)


def outside_squares(largest):
    """Whether positive finite magnitudes (a float or an array) lie outside SQUARES_SAFE."""
    low, high = SQUARES_SAFE
    return (largest > 0) & np.isfinite(largest) & ((largest < low) | (largest > high))


def square_safe_shift(largest: float) -> int:
    """The power of two bringing ``largest`` near 1 where it lies outside SQUARES_SAFE; 0 inside
    (and for 0 or a non-finite number: nothing to scale)."""
    return -math.frexp(largest)[1] if bool(outside_squares(largest)) else 0


def unit_frobenius(M: np.ndarray) -> np.ndarray:
    """M / its Frobenius norm, also where the norm's squares underflow or overflow (a camera in
    a tiny world unit has entries near 1e300): there M is first brought to a largest entry near 1
    by an exact power of two. For norms in [1e-150, 1e150] this is M / np.linalg.norm(M), the
    same floats as before."""
    with np.errstate(over="ignore", under="ignore"):
        size = float(np.linalg.norm(M))
    if SQUARES_SAFE[0] < size < SQUARES_SAFE[1]:
        return M / size
    largest = float(np.max(np.abs(M)))
    if not 0.0 < largest < math.inf:
        return M / size  # zero or not finite: nothing to scale (the caller's checks say why)
    scaled = np.ldexp(M, -math.frexp(largest)[1])
    return scaled / np.linalg.norm(scaled)


def residual_lengths(residuals: np.ndarray) -> np.ndarray:
    """The 2-norms of image residuals (..., 2) without squaring them (np.hypot): a residual below
    1.5e-162 squares to 0, and a scope check reading its length as 0 let a point whose residual is
    1e135 times max_residual be in scope (review 40)."""
    return np.hypot(residuals[..., 0], residuals[..., 1])


def norm_cost(residuals: np.ndarray, norm: str) -> float:
    # Method calls rather than np.sum and np.linalg.norm: the same sums, a few microseconds less
    # on the small arrays of a triangulation's inner loop.
    if norm == "L2L2":
        return float((residuals * residuals).sum())
    if norm == "L2L1":
        return float(lengths(residuals, 1).sum())
    if norm == "L1L1":
        return float(np.abs(residuals).sum())
    raise ValueError(f"unknown norm {norm!r}")
