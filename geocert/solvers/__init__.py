"""The estimators: pure numerics (numpy, scipy, clarabel; no web, queue or database imports), one
problem family a package, on the shared layer below them (geocert.core).

- ``fractional``: sums of ratios (triangulation, resection, homographies).
- ``autocalibration``, ``bilinear``, ``lines``, ``reconstruction``: the other families.
- ``orientation``, ``datasets``: orienting a projective reconstruction; the shared data's readers.
"""
