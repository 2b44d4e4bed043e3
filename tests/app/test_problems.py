"""GET /v1/problems advertises options the API accepts (quick tier: no server is started)."""

from __future__ import annotations

from geocert.app.api.routes.service import served_defaults
from geocert.app.schemas import JOB_REQUEST
from geocert.kinds import KINDS


def test_each_kinds_advertised_defaults_are_accepted_as_they_are():
    """The reconstruction's advertised defaults held the solver's ``detail``, which its request
    model refuses: submitting them as advertised was a 422."""
    for kind in KINDS:
        JOB_REQUEST.validate_python({**kind.example, "options": served_defaults(kind)})
