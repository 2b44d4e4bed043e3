"""The certificate verifier: the trust boundary a third party runs without our solver.

Numpy only (no conic solver is imported): it reads a certificate document, recomputes every bound
behind each certified claim from the raw data, and says which check failed when one does.
- ``checks``: what every kind shares (the document's format and hashes, options, each claim's
  cost and scope, a result's agreement with its certificate), and ``verify_any``, the entry point;
- ``adapters``: the verifier's own registry of the kinds a certificate may name, each with the
  numpy-only adapter that reads and checks its items (the service's kinds take their contract
  from it, never the reverse);
- ``autocalibration``, ``bilinear``, ``reconstruction`` (with ``reconstruction_stages``): the
  adapters of the kinds whose checks are their own; the fractional kinds' (triangulation,
  resection, homography) sit with their numerics in solvers.fractional.

It sits above the estimators: it reuses their numpy-only pieces (the relaxations it rebuilds, the
geometry) and they never import it; a solver's self-check (GEOCERT_SELF_VERIFY=1) reaches it
through core.self_check, where ``checks`` installs itself. docs/certificate.md explains
each step.
"""

from geocert.verify.checks import Report, verify_any, verify_arrays, verify_document

__all__ = ["Report", "verify_any", "verify_arrays", "verify_document"]
