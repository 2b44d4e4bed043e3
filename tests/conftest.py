"""Test-wide settings: property tests draw the same examples on every run (CI must not depend on
luck); set HYPOTHESIS_PROFILE=explore locally to draw new ones."""

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

# Every certified result the suites produce, in this process and in the workers it starts, is
# checked by the independent verifier before it is returned (solvers/verify.py): a result its own
# certificate does not prove raises SelfCheckFailed.
os.environ.setdefault("GEOCERT_SELF_VERIFY", "1")
