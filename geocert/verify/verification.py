"""What a kind's verification adapter is: the numpy-only object the verifier reads a kind's items
through (a kind's ``verification``, listed in verify/adapters.py). It reads an item's arrays from
the data (``read``, the one method every adapter defines); every other hook is optional, and its
default here (None: the verifier's own general check) is what the verifier does without it. The
verifier reads a hook through ``hook``, so an adapter that does not subclass Verification (the
fractional kinds' in verify/fractional.py, registered as virtual subclasses) gets the same
defaults."""

from __future__ import annotations

import abc
from typing import Any, Callable


class Verification(abc.ABC):
    """A kind's verification adapter (see verify/bilinear.py for one)."""

    domain: str
    """Where the kind's optimum is proven, in words (the scope statement's domain)."""

    proofs: dict[str, Callable[..., float]] = {}
    """Proof type -> ``check(item, options, proof, lower_claimed, solution, passed) -> bound``: the
    lower bound a certified item's proof establishes (a "trivial" proof, bound 0, is the
    verifier's own)."""

    @abc.abstractmethod
    def read(self, data: Any, index: int) -> tuple:
        """Item ``index``'s arrays, read strictly from the certificate's data (Invalid otherwise)."""

    def item(self, arrays: tuple, norm: str) -> Any:
        """The item the proofs and costs are checked on, built from ``read``'s arrays: what the
        residual claim's checks use (a kind with its own ``check_claim`` needs none)."""
        raise NotImplementedError(f"{type(self).__name__} checks its claims itself (check_claim): it builds no item")

    checked_options: Callable[[dict], dict] | None = None
    """``checked_options(options) -> dict``: the options a claim depends on, read and validated by
    the kind itself (a kind whose cost is not a norm of residuals). None: read as the residual
    kinds' are, with the kind's options class (verify.residual_options)."""

    scope_statement: Callable[[dict], dict] | None = None
    """``scope_statement(options) -> dict``: what a valid certificate of the kind proves, in words
    and numbers. None: the residual kinds' statement over ``domain``."""

    data_scope: Callable[[dict, dict, list], dict] | None = None
    """``data_scope(data, options, items) -> dict``: what the scope must add that the data and the
    claims decide (the autocalibration's reference camera, and its items whose proofs name none);
    {} when nothing. None: nothing."""

    option_names: tuple[str, ...] | None = None
    """The option names a certificate of the kind may state: its options class's fields (the
    document's options are ``dataclasses.asdict`` of them: kinds.documents), and any name an earlier
    form wrote. A name outside them is refused (no check reads it). None: the fields of the kind's
    options_type (the residual kinds'); a kind with neither states none to check."""

    claim_options: tuple[str, ...] | None = None
    """The options the problem hash covers. None: the verifier's CLAIM_OPTIONS."""

    hash_marks: dict | None = None
    """The form the kind's documents declare through the problem hash beyond its options
    (certificates.problem_hash's marks): determinacy.ESTIMATES_FORM for a kind stating
    determinacy estimates, whose intervals then each state their tolerance. A document hashed
    without it is of the kind's earlier form (its estimates may be read as written before
    intervals stated a tolerance, the report's scope saying so). None: no mark."""

    earlier_forms: tuple = ()
    """A kind whose problem hash came to cover more options: its earlier forms, newest first, each
    ``(options covered, statement(options) -> what the report's scope says of it)``."""

    data_items: str | None = None
    """The list of the data holding the items one each (the certificate has one item per entry).
    None: the kind's items are not its data's (autocalibration's stages: check_claims counts
    them)."""

    check_data: Callable[[Any], None] | None = None
    """``check_data(data)``: refuse (Invalid, check ``data``) what the data hold beyond the kind's
    members, top level and per item, before any item is read: a member no check reads would be
    taken for part of the problem. None: the data are read only through ``read``."""

    forget: Callable[[], None] | None = None
    """``forget()``: drop what the adapter remembers of one document (called before and after its
    items are checked). None: it remembers nothing."""

    proven_together: Callable[..., tuple] | None = None
    """``proven_together(data, options, items) -> (positions, checks)``: many claims proven at once,
    every check passed; the rest are checked one by one. None: each claim alone."""

    check_claim: Callable[..., tuple] | None = None
    """``check_claim(arrays, options, claim, claimed, lower_claimed, passed) -> (bound, rel_gap)``:
    the kind checks a certified claim's solution, scope and proof itself and names its tolerance.
    None: the residual claim's checks, through ``proofs``, with the options' rel_gap."""

    check_claims: Callable[[list, dict], None] | None = None
    """``check_claims(items, options)``: what ties the claims to each other (the stages of one
    solve), raising Invalid. None: nothing ties them."""

    scope_of_items: Callable[[list], dict] | None = None
    """``scope_of_items(items) -> dict``: numbers of the scope each item's proof states, added to
    the report's scope. None: none."""

    rel_gap_of: Callable[[dict, int], float] | None = None
    """``rel_gap_of(options, index) -> float``: the rel_gap item ``index`` was solved with (per
    stage). None: the options' rel_gap."""

    uncertified_statuses: tuple[str, ...] | None = None
    """The words an uncertified item's status may be. None: the verifier's UNCERTIFIED_STATUSES."""

    proves_infeasible: Callable[[Any, dict, dict], bool] | None = None
    """``proves_infeasible(data, claim, options) -> bool``: whether the data prove the item
    infeasible (its status "infeasible"). None: the kind never says infeasible."""

    solution_cost: Callable[[Any, dict, dict], float | None] | None = None
    """``solution_cost(data, claim, options)``: what an uncertified item's solution costs on the
    data (None when it returns none). None: an uncertified item states no cost."""

    check_result: Callable[..., dict | None] | None = None
    """``check_result(returned, document, verify, hashed=...) -> scope or None``: what else the
    result returns on the strength of its certificates (a reconstruction's cameras, against the
    camera certificate beside its points'). None: nothing else."""

    returned_scope: Callable[[], dict] | None = None
    """``returned_scope() -> dict``: what the report's scope says of the returned result (e.g. root
    regions in earlier words). None: nothing."""

    check_returned: Callable[[dict, dict, bool], None] | None = None
    """``check_returned(result, certificate, earlier_estimates)``: what else the result returns,
    derived from the claims, checked against them (``earlier_estimates``: whether the document's
    hash lets its estimates be of the earlier form, checks._check_hashes). None: nothing else."""

    estimates_of: Callable[[dict, dict], Any] | None = None
    """``estimates_of(result, certificate)``: the parts of the result whose determinacy is an
    estimate still (a kind proving some intervals). None: the whole result's."""

    job_outcomes: Callable[[dict], list] | None = None
    """``job_outcomes(result) -> [(status, certified), ...]``: a kind whose job is one item proving
    several claims (autocalibration's stages, a reconstruction's points) says what the job's
    outcomes are for its stats. None: the items under item_key."""


def hook(adapter: Any, name: str, otherwise: Any = None) -> Any:
    """An adapter's hook, or Verification's default for it (read only when the adapter has none:
    a member declared without a default, such as ``domain``, is the adapter's own); ``otherwise``
    stands for a hook that is None (not declared, or declared None) and only then: a value the
    adapter declares is used as declared, a falsy one too (``uncertified_statuses = ()`` allows no
    word, it does not fall back to the verifier's)."""
    value = getattr(adapter, name) if hasattr(adapter, name) else getattr(Verification, name)
    return otherwise if value is None else value
