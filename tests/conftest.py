"""Test-wide settings: property tests draw the same examples on every run (CI must not depend on
luck); set HYPOTHESIS_PROFILE=explore locally to draw new ones."""

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
