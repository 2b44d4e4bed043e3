"""Tightening a box before it is split, for any stage whose relaxation can cap the cost: each
coordinate minimised and maximised over the box's relaxation with the cost capped at the
incumbent's. What remains is split; the slabs cut off are leaves closed by a cut proof (a safe
dual bound), which the verifier rebuilds (proofs.check_leaves)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from geocert.solvers.core.bnb import Box
from geocert.solvers.core.certificates import LeafProof
from geocert.solvers.core.conic import ConicStatus, ReusableConicProgram
from geocert.solvers.core.cones import safe_lower_bound


@dataclass
class CutProof(LeafProof):
    """Every point of ``box`` costing at most ``upper_bound`` has sign * x[axis] >= value (a
    safe dual bound over the relaxation with the cost capped): the slab of the box beyond that
    value holds no such point."""

    axis: int = 0
    sign: float = 1.0
    value: float = 0.0


def tighten_box(build_capped: Callable, box: Box, cap: float, record: bool
                ) -> tuple[list[tuple[Box, CutProof]], Box | None]:
    """The slabs of the box its tightening cuts off, each with its cut, in a guillotine order
    (they and what remains partition the box), and what remains (None when nothing does).
    ``build_capped(lo, hi, cap)`` is the relaxation with the cost capped; its first variables are
    the box's coordinates."""
    try:
        program = build_capped(box.lo, box.hi, cap)
    except ValueError:
        return [], box
    if program is None:
        return [], box
    solver = ReusableConicProgram(lean=False)
    current_lo, current_hi = box.lo.copy(), box.hi.copy()
    slabs: list[tuple[Box, CutProof]] = []
    first = True
    for k in range(len(box.lo)):
        for sign in (1.0, -1.0):
            q = np.zeros_like(program.q)
            q[k] = sign
            result = solver.solve(q, program.A, program.b, program.cones) if first else solver.solve_objective(q)
            first = False
            if result.status is not ConicStatus.OPTIMAL:
                continue
            value = safe_lower_bound(q, program.A, program.b, program.cones, result.z, program.lower, program.upper)
            if not math.isfinite(value):
                continue
            side = value if sign > 0 else -value  # points costing <= cap: x_k >= side (or <= side)
            if sign > 0 and side > current_lo[k]:
                slab_hi = current_hi.copy()
                slab_hi[k] = min(side, current_hi[k])
                slab = Box(current_lo.copy(), slab_hi)
                current_lo[k] = side
            elif sign < 0 and side < current_hi[k]:
                slab_lo = current_lo.copy()
                slab_lo[k] = max(side, current_lo[k])
                slab = Box(slab_lo, current_hi.copy())
                current_hi[k] = side
            else:
                continue
            slabs.append((slab, CutProof(box, cap, "cut", result.z.copy() if record else None, cap,
                                         axis=k, sign=sign, value=value)))
            if current_lo[k] >= current_hi[k]:
                return slabs, None  # nothing of the box costs at most cap
    return slabs, Box(current_lo, current_hi)
