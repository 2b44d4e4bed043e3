"""What the estimators (geocert.solvers) and the verifier (geocert.verify) share, below both: the
branch-and-bound engine (bnb), the conic-solver boundary (conic), safe bounds from dual vectors
(cones), the certificate format (certificates), strict readers (strict) and small geometry
helpers (geometry). It imports nothing of geocert above it."""
