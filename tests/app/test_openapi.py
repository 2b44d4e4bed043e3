"""The checked-in OpenAPI spec is the app's (quick tier: no server is started)."""

from __future__ import annotations

import json
from geocert.app.cli import openapi_document
from tests.support import ROOT


def test_checked_in_spec_is_current():
    path = ROOT / "openapi" / "openapi.json"
    assert json.loads(path.read_text()) == openapi_document(), "run: geocert openapi --output openapi/openapi.json"
