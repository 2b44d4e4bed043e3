"""Sums of ratios (thesis chapter 5), the part the solver and the verifier share: the fractional
programs (charts, relaxation), one item and its program (items), the proofs' forms and their
checks (proof, stacked, convexity, the resection bounds), the determinacy estimates and the options."""
