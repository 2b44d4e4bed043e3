"""What the line solvers return: candidate motions, estimates (never certified)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


class Degenerate(ValueError):
    """The lines given do not fix the motion (parallel lines, lines in an epipolar plane, ...)."""


@dataclass
class Motion:
    """A candidate motion X_b = R X_a + t, with the algebraic residual of the equations it came
    from (the solvers' own ranking of candidates; RANSAC ranks by pixels)."""

    R: np.ndarray
    t: np.ndarray
    residual: float = 0.0


@dataclass
class PairEstimate:
    """A frame pair's motion as RANSAC and the refinement left it: an estimate, never certified."""

    status: str  # "estimate" or "failed"
    R: np.ndarray | None = None
    t: np.ndarray | None = None
    inliers: list[int] = field(default_factory=list)
    lines: int = 0
    iterations: int = 0
    solver: str = ""
    reason: str | None = None
    degenerate: list[int] = field(default_factory=list)
    rms_px: float | None = None
    refined: bool = False

    @property
    def inlier_ratio(self) -> float:
        return len(self.inliers) / self.lines if self.lines else 0.0
