"""Pipelines: multi-stage jobs (photos or tracks to a certified reconstruction) that call the
estimators of geocert.solvers. They sit above the solvers (the solvers import nothing from here)
and below the kinds (the wire contract)."""
