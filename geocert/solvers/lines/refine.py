"""The optional within-frame refinement: the motion (rotation vector and t) minimising the pixel
reprojection residuals of the inlier lines (geometry.reprojection_residuals: each line triangulated
from its four views under the motion, W's best rank-2 approximation, and its endpoints' distances
to its projections in the four views), with scipy.optimize.least_squares (robust soft-L1 loss at
the RANSAC threshold). The lines are eliminated (re-triangulated at every evaluation), not
parameters: a motion-only refinement, close to a two-frame bundle adjustment for small motion."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from geocert.solvers.lines.geometry import LineSet, log_rotation, reprojection_residuals, rodrigues
from geocert.solvers.lines.results import Motion


@dataclass
class RefineOptions:
    max_evaluations: int = 60
    loss_scale_px: float = 2.0


def refine(lines: LineSet, motion: Motion, options: RefineOptions | None = None) -> Motion:
    options = options or RefineOptions()
    R0 = motion.R

    def residuals(x: np.ndarray) -> np.ndarray:
        return reprojection_residuals(lines, rodrigues(x[:3]) @ R0, x[3:]).ravel()

    start = np.concatenate([np.zeros(3), motion.t])
    fit = least_squares(residuals, start, method="trf", loss="soft_l1", f_scale=options.loss_scale_px,
                        max_nfev=options.max_evaluations, x_scale="jac")
    if not np.all(np.isfinite(fit.x)):
        return motion
    R = rodrigues(fit.x[:3]) @ R0
    return Motion(R, fit.x[3:], float(np.sqrt(np.mean(fit.fun ** 2))))


__all__ = ["RefineOptions", "refine", "log_rotation"]
