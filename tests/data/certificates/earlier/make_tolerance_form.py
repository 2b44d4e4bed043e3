"""Write the stored documents of the estimates' form 1 (core.determinacy.FORMS[0]: every interval
states its tolerance, levels at 3 standard errors whatever the degrees of freedom), which today's
verifier reads in that form (tests/verify/test_estimates_forms.py). Run with the code of that form
on the path (a checkout of it, here /tmp/old), from anywhere:

    PYTHONPATH=/tmp/old .venv/bin/python tests/data/certificates/earlier/make_tolerance_form.py NAME ...
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.append(str(HERE.parents[3]))  # for tests.support (geocert: from PYTHONPATH)

from geocert.core.determinacy import ESTIMATES_FORM  # noqa: E402
from geocert.jobs.runner import solve_job  # noqa: E402
from geocert.kinds import get_kind  # noqa: E402
from tests.data.certificates.make_fixtures import write  # noqa: E402
from tests.support import map_job, seed  # noqa: E402


def resection_six_points_tolerance_form() -> dict:
    """Three resections from 6 points each (one residual degree of freedom): the maps whose levels
    the Student quantile changes most."""
    return solve_job(map_job(np.random.default_rng(seed("form 1", "resection")), "resection", 6, "L2L2", maps=3,
                             noise=0.5))


def autocalibration_stratified_tolerance_form() -> dict:
    """The kind's example (stratified), whose metric stage states the principal point's and skew's
    tolerances as a tenth of the focal length."""
    job = get_kind("autocalibration").example
    return solve_job({**job, "options": {**job.get("options", {}), "certificate": "full"}})


def autocalibration_four_views_tolerance_form() -> dict:
    """Four views (three modulus constraints for the plane's three unknowns): both stages warn
    no_redundancy, which form 1's verifier does not require."""
    from geocert.solvers.autocalibration import scenes

    scene = scenes.make_scene(4, 0.1, seed=1)
    return solve_job({"kind": "autocalibration", "data": scene.job_data(),
                      "options": {"time_limit_s": 60, "certificate": "full"}})


CASES = {f.__name__: f for f in (resection_six_points_tolerance_form, autocalibration_stratified_tolerance_form,
                                 autocalibration_four_views_tolerance_form)}


def main(names: list[str]) -> None:
    if ESTIMATES_FORM != {"determinacy": "every interval states its tolerance"}:
        raise RuntimeError(f"the code on the path writes the form {ESTIMATES_FORM!r}, not form 1")
    write(CASES, names, HERE)


if __name__ == "__main__":
    import geocert

    print(f"geocert from {Path(geocert.__file__).parent}")
    main(sys.argv[1:])
