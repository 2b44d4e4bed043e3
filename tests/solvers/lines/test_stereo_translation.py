"""Stereo lines: a frame pair's translation is either within 10% of its length or marked as not
determined, with the reason (issue 37). The narrow-baseline corridor walk of the issue (the
thesis's rig: 7.4 cm baseline, 90 degrees of field of view; 8 cm a frame; segments 2 to 8 m away;
0.5 px of noise; 30% of the lines matched wrongly): most of a corridor's lines run along the walk
and its floor's joints lie in epipolar planes, so the translation along the walk rests on a few
door frames, and the data leave it open by more than 10%; a pair that says otherwise must be
right. Both the polynomial and the incremental solver are held to it."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.solvers.lines import scenes


def job(rig, pairs: list[np.ndarray], solver: str) -> dict:
    return {"kind": "stereo_lines", "options": {"solver": solver, "sample_size": 3},
            "data": {"rig": {"K_left": rig.K_left.tolist(), "K_right": rig.K_right.tolist(), "R": rig.R.tolist(),
                             "t": rig.t.tolist()}, "matches": [p.tolist() for p in pairs]}}


def true_steps(poses) -> list[np.ndarray]:
    return [tb - Rb @ Ra.T @ ta for (Ra, ta), (Rb, tb) in zip(poses, poses[1:])]


def judged_pairs(rig, poses, pairs, solver: str) -> list[tuple[float, dict]]:
    """(translation error over the step's length, the pair) for every frame pair of a walk."""
    result = solve_job(job(rig, pairs, solver))
    out = []
    for truth, item in zip(true_steps(poses), result["pairs"]):
        assert item["status"] == "estimate", item["reason"]
        out.append((float(np.linalg.norm(np.array(item["t"]) - truth) / np.linalg.norm(truth)), item))
    return out


@pytest.mark.parametrize("solver", ["incremental", "polynomial"])
def test_a_corridor_walks_translation_is_within_10_percent_or_marked(solver):
    wrong_and_marked = 0
    for seed in range(3):
        rig, poses, pairs = scenes.corridor_walk(np.random.default_rng(seed), frames=6)
        for error, item in judged_pairs(rig, poses, pairs, solver):
            if error > 0.1:
                assert item["translation_determined"] is False, (seed, error, item["determinacy"])
                assert item["reason"].startswith("the translation is not determined"), item["reason"]
                wrong_and_marked += 1
            else:
                assert item["translation_determined"] is not None
    assert wrong_and_marked > 0  # the scene is the hard one it is meant to be


@pytest.mark.parametrize("solver,least", [("incremental", 3), ("polynomial", 1)])
def test_a_well_seen_translation_is_determined_and_right(solver, least):
    """Lines 1.5 to 4 m away all round the view, 30 cm a frame: the pairs that say their
    translation is determined are within 10% of it, and some say so (the marking is not merely
    always on; the refinement often stops short of the optimum, and its intervals are then
    stretched to take in the step to it, which leaves some right translations marked). Sixteen
    pairs: the polynomial solver's RANSAC finds one of the first six determined or none as the
    rounding of its equations goes (one in six in metres, none in units of the scene's depth; two
    of the sixteen either way at the estimates' form 1, one at form 2's Student level, which
    widens its intervals; incremental six)."""
    rng = np.random.default_rng(11)
    determined = 0
    for _ in range(16):
        scene = scenes.pair_scene(rng, 80, noise_px=0.5, outlier_fraction=0.3, degrees=2.0, metres=0.3,
                                  depth=(1.5, 4.0))
        poses = [(np.eye(3), np.zeros(3)), (scene.R, scene.t)]
        (error, item), = judged_pairs(scene.rig, poses, [scene.segments], solver)
        if item["translation_determined"]:
            determined += 1
            assert error <= 0.1, (error, item["determinacy"])
    assert determined >= least
