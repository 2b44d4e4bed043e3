"""A certificate's options are the ones its kind's solver takes: an unknown option name (an
``x_intrinsics`` beside a reconstruction's ``intrinsics``, a misspelt ``max_residul``) was ignored,
and the document verified as if it stated a request the solver served; it is refused now, naming
the option (check ``options``). Every stored document, of every kind, states only known names."""

from __future__ import annotations

import copy
import dataclasses

import pytest

from geocert.verify.checks import verify_any, verify_document
from tests.verify.test_stored_certificates import NAMES, stored

EMBEDDED = ("certificate", "camera_certificate", "calibration_certificate")


def test_the_reconstructions_names_are_its_options_class_fields():
    """run_control.OPTION_NAMES (the verifier's, below the pipeline) are ReconstructionOptions'
    fields, which certificate_document writes."""
    from geocert.pipelines.reconstruction.options import ReconstructionOptions
    from geocert.verify.checks import option_names

    assert sorted(option_names("reconstruction")) == sorted(f.name for f in dataclasses.fields(ReconstructionOptions))


@pytest.mark.parametrize("name", NAMES)
def test_every_stored_document_states_known_names_only(name):
    from geocert.verify.checks import option_names

    result = stored(name)
    for member in EMBEDDED:
        if member in result:
            document = result[member]
            assert set(document["options"]) <= set(option_names(document["kind"])), (member, document["kind"])


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("member", EMBEDDED)
def test_an_unknown_option_is_refused_naming_it(name, member):
    """Found: each stored document, or a certificate it carries, verified with an option no kind
    has added beside its own (an unknown name changes no hash: the hashes cover named options)."""
    result = stored(name)
    if member not in result:
        pytest.skip(f"{name} carries no {member}")
    forged = copy.deepcopy(result)
    unknown = "x_intrinsics" if forged[member]["kind"] == "reconstruction" else "max_residul"
    forged[member]["options"][unknown] = forged[member]["options"].get("intrinsics", 1.0)
    assert not verify_any(forged).valid  # (a carried certificate's failure is the result's: check returned)
    failure = verify_document(forged[member]).first_failure
    assert failure["check"] == "options" and f"options/{unknown}" in failure["detail"], failure
