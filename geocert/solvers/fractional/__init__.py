"""Sums of ratios (thesis chapter 5): triangulation, resection and homographies as fractional
programs (charts), their convex relaxations (relaxation), the search (search), the two kinds'
solvers (triangulation, maps) and what the verifier needs of them (items, proof)."""
