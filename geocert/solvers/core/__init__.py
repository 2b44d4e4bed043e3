"""What every problem family shares: the branch-and-bound engine (bnb), the conic-solver boundary
(conic), safe bounds from dual vectors (cones), the certificate format (certificates) and small
geometry helpers (geometry)."""
