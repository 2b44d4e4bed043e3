"""The verification adapter is an abstract base class (geocert/verify/verification.py): every hook
the verifier reads from a kind's adapter is declared there with its default and what it means,
every adapter the verifier lists is one, and a contract whose adapter is not is refused."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from geocert.verify import adapters
from geocert.verify.adapters import VERIFIED_KINDS, VerifiedKind
from geocert.verify.verification import Verification, hook

VERIFY = Path(adapters.__file__).parent


def documented_members() -> set[str]:
    """Verification's members that carry a docstring (a method's own, an attribute's the string
    literal after it)."""
    body = next(node for node in ast.parse((VERIFY / "verification.py").read_text()).body
                if isinstance(node, ast.ClassDef) and node.name == "Verification").body
    documented = set()
    for node, following in zip(body, body[1:] + [None]):
        if isinstance(node, ast.FunctionDef) and ast.get_docstring(node):
            documented.add(node.name)
        elif isinstance(node, (ast.AnnAssign, ast.Assign)) and isinstance(following, ast.Expr) \
                and isinstance(following.value, ast.Constant) and isinstance(following.value.value, str):
            target = node.target if isinstance(node, ast.AnnAssign) else node.targets[0]
            documented.add(target.id)
    return documented


def test_every_hook_the_verifier_reads_is_declared_and_documented():
    read = set()
    for path in VERIFY.glob("*.py"):
        read |= set(re.findall(r'\bhook\([^,()]+(?:\([^()]*\))?, "(\w+)"[,)]', path.read_text()))
    assert {"checked_options", "job_outcomes", "check_claim", "claim_options", "forget"} <= read  # the reading is found
    assert read <= documented_members(), read - documented_members()
    for path in set(VERIFY.glob("*.py")) - {VERIFY / "verification.py"}:  # the verifier asks an adapter nothing by getattr with a default of its own
        assert not re.search(r'getattr\((adapter|_adapter\(|kind\.verification)', path.read_text()), path.name


def test_every_listed_adapter_is_a_verification():
    for kind in VERIFIED_KINDS.values():
        assert isinstance(kind.verification, Verification), kind.name


def test_a_hook_an_adapter_leaves_out_reads_as_the_default():
    triangulation = VERIFIED_KINDS["triangulation"].verification  # defined below the verifier
    assert hook(triangulation, "check_claims") is None and hook(triangulation, "earlier_forms") == ()
    assert hook(VERIFIED_KINDS["autocalibration"].verification, "job_outcomes") is not None


def test_a_contract_whose_adapter_is_not_a_verification_is_refused(monkeypatch):
    monkeypatch.setattr(adapters, "VERIFIED_KINDS", dict(VERIFIED_KINDS))

    class Duck:
        domain = "anywhere"

        def read(self, data, index):
            return ()

    with pytest.raises(TypeError, match="not a geocert.verify.verification.Verification"):
        adapters.register(VerifiedKind("duck", "items", ("x",), Duck()))
    assert "duck" not in adapters.VERIFIED_KINDS


class _Declares(Verification):
    """A toy adapter declaring falsy hooks: no uncertified word allowed, no option hashed."""

    domain = "nowhere"
    uncertified_statuses = ()
    claim_options = ()

    def read(self, data, index):
        return ()


@pytest.fixture
def declares(monkeypatch):
    monkeypatch.setattr(adapters, "VERIFIED_KINDS", dict(VERIFIED_KINDS))
    adapters.register(VerifiedKind("declares", "items", ("x",), _Declares()))
    return "declares"


def test_a_falsy_hook_is_read_as_declared(declares):
    """hook(adapter, name, otherwise): only a hook that is None takes the verifier's default; the
    checks read `hook(...) or default`, so an adapter declaring `uncertified_statuses = ()` (no word
    allowed) got the verifier's four words (fails on main: hook takes no default there)."""
    from geocert.verify.checks import UNCERTIFIED_STATUSES

    adapter = adapters.VERIFIED_KINDS[declares].verification
    assert hook(adapter, "uncertified_statuses", UNCERTIFIED_STATUSES) == ()
    assert hook(adapter, "check_claims", "default") == "default"  # undeclared: Verification's None, then otherwise


def test_an_adapter_allowing_no_uncertified_word_refuses_every_one(declares):
    """The verifier's own check (checks.uncertified_claim): with `uncertified_statuses = ()` the
    status "not_certified" is refused; on main the falsy tuple fell back to the verifier's words
    and the item was accepted."""
    from geocert.core.strict import Invalid
    from geocert.verify.checks import uncertified_claim

    with pytest.raises(Invalid, match="an uncertified item's status is one of"):
        uncertified_claim(declares, {"items": [[0.0]]}, {}, {"index": 0, "status": "not_certified",
                                                             "certified": False})


def test_an_adapter_hashing_no_option_is_hashed_over_none(declares):
    """`claim_options = ()`: the problem hash covers no option (on main the empty tuple fell back
    to CLAIM_OPTIONS, the residual kinds' four)."""
    from geocert.core.certificates import data_hash, problem_hash
    from geocert.verify.checks import _check_hashes

    data, options = {"items": []}, {"norm": "L2L2", "rel_gap": 1e-3}
    document = {"kind": declares, "data": data, "options": options, "data_sha256": data_hash(declares, data),
                "problem_sha256": problem_hash(declares, data, {}, ())}
    assert _check_hashes(document, options)[0] == ()
