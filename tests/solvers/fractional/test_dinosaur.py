"""Real data: the Oxford Dinosaur (36 projective cameras, 4983 tracks; Oxford VGG)."""

import numpy as np
import pytest

from geocert.solvers.datasets import load_dinosaur
from geocert.solvers.fractional.triangulation import TriangulationOptions, triangulate

from tests.support import shared_data


pytestmark = pytest.mark.slow  # real servers, real data or SCIP: the full run only


@pytest.fixture(scope="module")
def dinosaur():
    return load_dinosaur(shared_data("oxford_dinosaur"))


class TestDinosaur:
    def test_every_track_certified_and_in_front(self, dinosaur):
        cameras, tracks = dinosaur
        assert len(tracks) == 4983
        options = TriangulationOptions(norm="L2L2", rel_gap=1e-3)
        for index, track in enumerate(tracks):
            cams = cameras[track.views]
            result = triangulate(cams, track.points, options)
            assert result.certified, (index, result.status, result.reason)
            X = np.array(result.point + [1.0]) if not result.at_infinity else np.array(result.point)
            assert np.all(cams[:, 2, :] @ X > 0), f"track {index}: returned point behind a camera"
            assert result.gap <= max(options.abs_gap, options.rel_gap * result.cost) * (1 + 1e-9)
            region = result.certificate
            if region is None:  # certified by the trivial bound: cost within abs_gap of 0
                assert result.cost <= options.abs_gap
                continue
            # The returned point lies in the root region the certificate states.
            z = np.array(region.functionals) @ X / (np.array(region.denominator) @ X)
            assert np.all(z >= np.array(region.lower) - 1e-9) and np.all(z <= np.array(region.upper) + 1e-9)
