"""Sums of ratios (thesis chapter 5): the branch-and-bound search (search, sublevel_search), the
two kinds' solvers (triangulation, maps) and the batched tracks (many_tracks), on the programs and
proofs of geocert.formulations.fractional."""
