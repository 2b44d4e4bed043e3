"""What a solver writes and the verifier checks, shared by both and owned by neither: each problem
family's programs and relaxations, frames, readers, option dataclasses, proofs' JSON forms and the
checks of those proofs. It imports only ``geocert.core`` below it; the estimators
(``geocert.solvers``) and the verifier (``geocert.verify``) import it, so that the verifier imports
nothing it checks (docs/architecture.md).

- ``fractional``: sums of ratios (triangulation, resection, homographies).
- ``autocalibration``, ``bilinear``, ``reconstruction``: the other certified families.
"""
