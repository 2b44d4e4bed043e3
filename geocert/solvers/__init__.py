"""Pure numerics (numpy, scipy, clarabel; no web, queue or database imports).

- ``core``: what every problem family shares: the branch-and-bound engine, the conic boundary,
  safe bounds from dual vectors, the certificate format, strict readers, geometry helpers.
- ``fractional``: sums of ratios (triangulation, resection, homographies).
- ``verify``: the stand-alone certificate verifier (no conic solver imported).
- ``orientation``, ``datasets``: orienting a projective reconstruction; the shared data's readers.
"""
