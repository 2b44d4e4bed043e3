"""A track's depth estimate (determinacy's ``depth_view0``, the point's distance from its first
view's centre) written under one BLAS kernel verifies under another, for points nearer a camera's
centre than the centre is to the origin by many orders (the depth is then a difference of numbers
far larger than itself). Before: the centres were an SVD's null vectors, which OpenBLAS's Haswell
and Prescott kernels round otherwise; a hostile scene's point 2e-9 from a centre 20 units off the
origin read depths 2.5e-5 of themselves apart, refused at the value (held to 1e-9 of itself). Now
both sides compute the centres by cofactors and the length by one sum in a fixed order
(fractional.fixed_order.camera_centres, determinacy._length): one float on every machine.
Cross-kernel: subprocesses under OPENBLAS_CORETYPE=Haswell and Prescott (review 35's _run), skipped
without AVX2."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from geocert.formulations.fractional import fixed_order
from tests.verify.test_forgeries_review35 import _has_avx2, _run

DISTANCES = (1e-3, 1e-6, 2e-9, 1e-10)  # of the point from camera 0's centre, which is 20 off the origin


def _near_centre_job(seed: int) -> dict:
    """Three views, their centres about 20 from the origin; tracks whose points lie DISTANCES from
    view 0's centre in front of it, seen with 0.5 px of noise."""
    rng = np.random.default_rng(seed)
    K = np.array([[900.0, 0, 320], [0, 900, 240], [0, 0, 1]])
    cameras, centres = [], []
    for _ in range(3):
        R = Rotation.from_rotvec(rng.normal(0, 0.2, 3)).as_matrix()
        C = np.array([20.0, 0, 0]) + rng.normal(0, 1, 3)
        cameras.append(K @ np.hstack([R, (-R @ C)[:, None]]))
        centres.append(C)
    cameras = np.array(cameras)
    tracks = []
    for distance in DISTANCES:
        for _ in range(3):
            axis = np.linalg.inv(K @ cameras[0][:, :3] / 900) @ np.append(rng.uniform(-0.2, 0.2, 2), 1.0)
            X = centres[0] + distance * axis / np.linalg.norm(axis)
            x = np.einsum("vij,j->vi", cameras, np.append(X, 1.0))
            tracks.append({"views": [0, 1, 2], "points": (x[:, :2] / x[:, 2:] + rng.normal(0, 0.5, (3, 2))).tolist()})
    return {"kind": "triangulation", "data": {"cameras": cameras.tolist(), "tracks": tracks},
            "options": {"norm": "L2L2", "certificate": "full"}}


@pytest.fixture(scope="module")
def across_kernels(tmp_path_factory) -> dict:
    if not _has_avx2():
        pytest.skip("needs OpenBLAS's Haswell and Prescott kernels (x86-64 with AVX2)")
    directory = tmp_path_factory.mktemp("depth")
    jobs = {f"seed{seed}": _near_centre_job(seed) for seed in (1, 2, 3)}
    written = {kernel: _run(kernel, "solve", jobs, directory) for kernel in ("Haswell", "Prescott")}
    checked = {"Haswell": _run("Prescott", "verify", written["Haswell"], directory),
               "Prescott": _run("Haswell", "verify", written["Prescott"], directory)}
    return {"written": written, "checked": checked}


def test_near_centre_depths_verify_under_another_kernel(across_kernels):
    failures = {(writer, name): verdict for writer, verdicts in across_kernels["checked"].items()
                for name, verdict in verdicts.items() if not verdict[0]}
    assert not failures


def test_every_near_centre_track_states_its_depth(across_kernels):
    """The premise: each writer states every track's depth, down to points 1e-10 from the centre
    (near the centre, not at it). The points themselves differ between kernels in their last
    digits (the solver's path), and each depth is its own point's."""
    for kernel, written in across_kernels["written"].items():
        for name, result in written.items():
            depths = [next(i["value"] for i in track["determinacy"]["intervals"] if i["name"] == "depth_view0")
                      for track in result["tracks"]]
            assert len(depths) == len(DISTANCES) * 3 and min(depths) < 1e-9 and max(depths) > 1e-4, (kernel, name)


def test_cofactor_centres_are_null_vectors_at_any_scale():
    """fixed_order.camera_centres: P c = 0 to the products' rounding, and the same floats for a
    camera scaled by any power of two (its scaling is exact) from 2^-1000 to 2^1000."""
    rng = np.random.default_rng(0)
    P = rng.normal(size=(6, 3, 4))
    c = fixed_order.camera_centres(P)
    scaled = P / np.abs(P).max(axis=(1, 2))[:, None, None]
    unit = c / np.abs(c).max(axis=1, keepdims=True)
    assert np.abs(np.einsum("kij,kj->ki", scaled, unit)).max() < 1e-14
    for exponent in (-1000, -3, 7, 1000):
        assert np.array_equal(fixed_order.camera_centres(np.ldexp(P, exponent)), c)
