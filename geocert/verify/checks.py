"""Check a certificate document with linear algebra only (no conic solver is imported here).

The checks every kind shares live here: the document's format and hashes, the options a claim
depends on, each certified claim's fields, its solution's cost and scope recomputed from the raw
data, and the agreement of a result with its certificate. What depends on the kind comes from its
verification adapter in the verifier's own registry (adapters.py; the service's kinds take
their verification contract from it, never the reverse): how to read an item's data and rebuild its
program, and which proof types it takes ("trivial" for every kind; "branch_and_bound" for the
fractional kinds, checked in geocert.formulations.fractional.proof; room for others, e.g. "sdp_dual").
docs/certificate.md explains each step.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from geocert.core import exact, self_check, summary_notes
from geocert.core.cones import rounding_uncounted
from geocert.core.self_check import SelfCheckFailed
from geocert.core.certificates import (BOUND_TOLERANCE, CLAIM_OPTIONS, FORMAT, OBJECTIVE_TOLERANCE, VERSION,
                                       data_digest, data_hash, problem_hash)
from geocert.core.geometry import cost_rounding, is_number, norm_cost, residual_lengths
from geocert.core.determinacy import CURRENT_FORM, ESTIMATES_FORM, FORMS, lacked, reading
from geocert.verify.notes import check_notes
from geocert.core.strict import (WORK_BASE, WORK_PER_UNIT, Invalid, document_size, nesting_depth,
                                 informational, number as _number, printable_tree, record, same, same_counts,
                                 work_budget)
from geocert.verify import residual_claims
from geocert.verify import estimates
from geocert.verify.verification import hook

MAX_DEPTH = 64
CHECKS = ("format", "data_hash", "options", "data", "claim", "objective", "scope", "program", "root_region",
          "tightening", "coverage", "leaf_bounds", "convexity", "sublevel_bound", "proven_interval", "lower_bound", "gap", "returned")


@dataclass
class Report:
    """``checks``: each check in order with how many items passed it, and its first failure;
    ``scope``: what a valid document proves, and for which problem."""

    valid: bool
    checks: list[dict] = field(default_factory=list)
    first_failure: dict | None = None
    items_checked: int = 0
    items_skipped: int = 0
    scope: dict | None = None
    discounted: list = field(default_factory=list)  # {"item", "lower_bound", "proven"}: see verify_arrays
    within_abs_gap: list = field(default_factory=list)  # items whose gap only abs_gap allows: see _verify

    def as_dict(self) -> dict:
        """The report as JSON writes it; its texts quote the document (a member name in a
        failure's detail), so a lone surrogate there is written as its escape (printable_tree)."""
        return printable_tree({"valid": self.valid, "checks": self.checks, "first_failure": self.first_failure,
                               "items_checked": self.items_checked, "items_skipped": self.items_skipped,
                               "scope": self.scope})


# --- the problem: options, data, one item ---------------------------------------------------

def checked_options(kind: str, options: Any) -> dict:
    """The options a claim depends on (the norm, the scope: max_residual, each residual's pixel
    distance, and the gap tolerances), read strictly and validated by the kind's own options
    class, exactly as the solver validates them."""
    if not isinstance(options, dict):
        raise Invalid("options", "options must be an object")
    _check_option_words(options)
    own = hook(_adapter(kind), "checked_options")
    if own is not None:  # a kind whose cost is not a norm of residuals reads its own
        return own(options)
    return residual_options(kind, options)


def _check_option_words(options: dict) -> None:
    """options.certificate and options.detail (what a result carries, never what is proven),
    when the echo states them, are words the solvers take (fractional.options: CERTIFICATE_MODES,
    DETAIL_MODES): an echo stating another states a request no solver served."""
    from geocert.formulations.fractional.options import CERTIFICATE_MODES, DETAIL_MODES

    for name, words in (("certificate", CERTIFICATE_MODES), ("detail", DETAIL_MODES)):
        value = options.get(name)
        if value is not None and not (isinstance(value, str) and value in words):
            raise Invalid("options", f"options/{name}: must be one of {', '.join(words)}, got {value!r:.40}")


def option_names(kind: str) -> tuple[str, ...] | None:
    """The option names a certificate of ``kind`` may state (its adapter's option_names, or its
    options_type's fields); None: the kind declares neither."""
    names = hook(_adapter(kind), "option_names")
    options_type = _kind(kind).options_type
    if names is None and options_type is not None and dataclasses.is_dataclass(options_type):
        names = tuple(entry.name for entry in dataclasses.fields(options_type))
    return names


def _check_option_names(kind: str, options: Any) -> None:
    """A certificate's options are the ones its kind's solver takes (option_names): an option no
    check reads (``x_intrinsics`` beside ``intrinsics``, a misspelt ``max_residul``) states a
    request no solver served, and a reader would take it for part of what is proven, so it is
    refused, naming it, as a result's unknown member is."""
    names = option_names(kind)
    if names is None or not isinstance(options, dict):
        return
    unknown = sorted(str(name) for name in set(options) - set(names))
    if unknown:
        raise Invalid("options", f"options/{unknown[0]:.60}: no {kind} certificate has this option (its options: "
                                 f"{', '.join(sorted(names))}); an option no check reads claims nothing, so it is "
                                 "refused")


def residual_options(kind: str, options: dict) -> dict:
    """checked_options of a kind whose cost is a norm of residuals: norm, gaps, max_residual."""
    return residual_claims.checked_options(_kind(kind).options_type, options, run_control=True)


def _kind(kind: Any):
    """The kind's verification contract, from the verifier's registry; a kind not served is invalid."""
    # imported here: the adapters import modules (fractional.maps, .triangulation) that import this one
    from geocert.verify.adapters import VERIFIED_KINDS

    if not isinstance(kind, str) or kind not in VERIFIED_KINDS:
        raise Invalid("format", f"kind {kind!r:.40} is not served (served: {', '.join(VERIFIED_KINDS)})")
    return VERIFIED_KINDS[kind]


def _adapter(kind: Any):
    """The kind's verification adapter."""
    return _kind(kind).verification


def scope_statement(kind: str, options: dict) -> dict:
    """What a valid certificate of this kind proves, in words and numbers."""
    own = hook(_adapter(kind), "scope_statement")
    if own is not None:
        return own(options)
    return residual_claims.scope(kind, _adapter(kind).domain, options)


def verify_document(document: Any) -> Report:
    """Check a certificate document (the ``certificate`` member of a result with
    ``options.certificate = "full"``)."""
    return _verify(document, None)


CERTIFICATE_MEMBERS = {"format", "version", "kind", "options", "data", "data_sha256", "problem_sha256", "items"}


def find_certificate(document: Any) -> tuple[dict, dict | None] | None:
    """(certificate, the result that returns it or None) from a certificate, result or job
    document; None when the document carries no certificate."""
    if not isinstance(document, dict):
        return None
    if document.get("format") is not None:
        return document, None  # a bare certificate (_verify refuses members it has not)
    if isinstance(document.get("result"), dict):  # a job document
        document = document["result"]
    if isinstance(document.get("certificate"), dict):  # a result document
        return document["certificate"], document
    return None


def estimates_kind(document: Any) -> str | None:
    """The kind of a result or job document when that kind issues estimates, never certificates
    (its ``certifies`` is False, e.g. stereo_lines); None otherwise."""
    if not isinstance(document, dict):
        return None
    inner = document["result"] if isinstance(document.get("result"), dict) else document
    name = inner.get("kind", document.get("kind"))
    from geocert.verify.adapters import VERIFIED_KINDS

    if isinstance(name, str) and name in VERIFIED_KINDS and not VERIFIED_KINDS[name].certifies:
        return name
    return None


def verify_any(document: Any) -> Report:
    """Check what ``geocert verify`` and ``POST /v1/certificates/verify`` take: a certificate
    document, a result document carrying one, or a job document carrying such a result. For a
    result or job, every item it returns must also equal the item its certificate proves."""
    found = find_certificate(document)
    if found is None:
        uncertified = estimates_kind(document)
        detail = (f"{uncertified} results are estimates, never certified: there is no certificate, so nothing to "
                  "verify" if uncertified is not None else
                  "no certificate in this document (a job or result solved with options.certificate = \"full\" "
                  "carries one)")
        report = Report(valid=False, first_failure={"check": "format", "item": None, "detail": detail})
        report.checks = [{"name": "format", "passed": 0, "failed": 1}]
        return report
    report = _verify(*found)
    if report.valid and found[1] is not None and found[1] is not document:  # a job document
        try:
            check_job(document, found[1])
        except Invalid as exc:
            report.valid = False
            report.first_failure = {"check": exc.check, "item": None, "detail": exc.detail}
            tally = next((c for c in report.checks if c["name"] == exc.check), None)
            if tally is None:
                report.checks.append(tally := {"name": exc.check, "passed": 0, "failed": 0})
            tally["failed"] += 1
    return report


# A job's statuses once it has ended with its result (service.jobs): "cancelled" when an item was
# stopped (or a cancel came after every item had finished: a weaker claim, accepted).
ENDED_WITH_RESULT = ("succeeded", "cancelled")


# The members of the service's job document and its progress (geocert.app.schemas.Job and
# JobProgress; tests/verify/test_forgeries_review7.py checks they agree).
JOB_MEMBERS = ("id", "kind", "status", "created_at", "started_at", "finished_at", "progress", "result", "error",
               "links", "webhook")
PROGRESS_MEMBERS = ("stage", "items_total", "items_done", "items_certified", "tracks_total", "tracks_done", "nodes",
                    "open_boxes", "lower_bound", "upper_bound", "gap_abs", "gap_rel", "elapsed_s")


def check_job(job: dict, result: dict) -> None:
    """A job document's own fields, which a user of GET /v1/jobs/{id} reads first, say what its
    result does: its kind is the result's; its status is one a job ends with beside its result
    ("succeeded" only when no item was cancelled; a failed job's partial result is verified as a
    result document); and its progress (when it has one) is the one the service recomputes from
    the result when the job ends (workers.tasks.final_progress): items_total, items_done (the
    items not cancelled), items_certified and nodes from stats, no open box, and the bounds the
    sums of the lower bounds and costs of the items stating both; a succeeded job states no error.
    A member the document does not state claims nothing and is not asked for; a member no job
    document has (the service's Job and JobProgress models: JOB_MEMBERS, PROGRESS_MEMBERS) is
    refused, as a result's are."""
    extra = sorted(set(job) - set(JOB_MEMBERS))
    progress = job.get("progress")
    extra += [f"progress/{name}" for name in sorted(set(progress) - set(PROGRESS_MEMBERS))] \
        if isinstance(progress, dict) else []
    if extra:
        raise Invalid("returned", f"the job document has a member {extra[0]!r:.60} no job document has (its members: "
                                  f"{', '.join(JOB_MEMBERS)}); a member no check reads claims nothing, so it is refused")
    if "kind" in job and job["kind"] != result.get("kind"):  # a member not stated claims nothing
        raise Invalid("returned", f"the job's kind {job.get('kind')!r:.40} is not its result's "
                                  f"{result.get('kind')!r:.40}")
    if job.get("status") in ENDED_WITH_RESULT and job.get("error") is not None:
        raise Invalid("returned", f"a {job['status']} job's error is null (the service states one only for a job "
                                  f"that failed), this job's is {job['error']!r:.80}")
    _check_job_members(job)
    if "status" not in job and job.get("progress") is None:
        return
    stats = result.get("stats")
    if not isinstance(stats, dict) or not isinstance(stats.get("statuses"), dict):
        raise Invalid("returned", "a job document stating its status or progress has a result stating its stats "
                                  "(items, certified, nodes, statuses)")
    cancelled = stats["statuses"].get("cancelled", 0)
    status = job.get("status", "cancelled")  # none stated: read as the weakest (it claims nothing)
    if status not in ENDED_WITH_RESULT or (status == "succeeded" and cancelled):
        raise Invalid("returned", f"the job's status {status!r:.40} is not one a job ends with beside this result "
                                  f"({'cancelled' if cancelled else 'succeeded or cancelled'}; a failed job's partial "
                                  "result is verified as a result document)")
    progress = job.get("progress")
    if progress is None:
        return
    if not isinstance(progress, dict):
        raise Invalid("returned", "progress must be an object")
    expected = {"items_total": stats.get("items"), "tracks_total": stats.get("items"),
                "items_done": stats.get("items", 0) - cancelled, "tracks_done": stats.get("items", 0) - cancelled,
                "items_certified": stats.get("certified"), "nodes": stats.get("nodes"), "open_boxes": 0}
    for name, value in expected.items():
        if name in progress and not same(progress[name], value):
            raise Invalid("returned", f"progress/{name} is {progress[name]!r:.40}, its result gives {value!r:.40}")
    _check_job_bounds(progress, result)


# The webhook's state as the service writes it (geocert.app.schemas.WebhookState).
WEBHOOK_MEMBERS = ("url", "state", "attempts", "last_error", "delivered_at")
WEBHOOK_STATES = ("waiting", "retrying", "delivered", "failed", "refused")


def _check_job_members(job: dict) -> None:
    """A job document's own members, each of the type the service's Job model gives it: its id a
    string and each link it states the job's own URL (jobs.store.links), its times numbers of seconds
    (created_at stated; started_at and finished_at null or numbers), its progress's counts and
    elapsed_s numbers >= 0 and its stage null or words, its webhook null or the webhook's state."""
    job_id = job.get("id")
    if "id" in job and not isinstance(job_id, str):
        raise Invalid("returned", f"the job's id must be a string, got {job_id!r:.40}")
    if "links" in job:
        base = f"/v1/jobs/{job_id}"
        own = {"self": base, "events": f"{base}/events", "cancel": f"{base}/cancel"}
        links = job["links"]
        if not (isinstance(job_id, str) and isinstance(links, dict)
                and all(name in own and url == own[name] for name, url in links.items())):
            raise Invalid("returned", f"links must point at the job's own URLs ({own!r:.120}), got {links!r:.120}")
    for name in ("created_at", "started_at", "finished_at"):
        value = job.get(name)
        if name in job and not ((value is None and name != "created_at") or (is_number(value) and value >= 0)):
            raise Invalid("returned", f"{name} must be {'' if name == 'created_at' else 'null or '}a time in seconds "
                                      f"(a number >= 0), got {value!r:.40}")
    progress = job.get("progress")
    if isinstance(progress, dict):
        for name in ("elapsed_s", "nodes", "open_boxes", "items_done", "items_total", "tracks_done", "tracks_total"):
            value = progress.get(name)
            if value is not None and not (is_number(value) and value >= 0 and (name == "elapsed_s" or type(value) is int)):
                raise Invalid("returned", f"progress/{name} must be {'a number' if name == 'elapsed_s' else 'a count'} "
                                          f">= 0, got {value!r:.40}")
        if progress.get("stage") is not None and not isinstance(progress["stage"], str):
            raise Invalid("returned", f"progress/stage must be null or a stage's name, got {progress['stage']!r:.40}")
    webhook = job.get("webhook")
    if webhook is None:
        return
    extra = sorted(set(webhook) - set(WEBHOOK_MEMBERS)) if isinstance(webhook, dict) else []
    if not isinstance(webhook, dict) or extra or not isinstance(webhook.get("url"), str) \
            or webhook.get("state") not in WEBHOOK_STATES or not (type(webhook.get("attempts")) is int
                                                                  and webhook["attempts"] >= 0) \
            or not (webhook.get("last_error") is None or isinstance(webhook["last_error"], str)) \
            or not (webhook.get("delivered_at") is None or (is_number(webhook["delivered_at"])
                                                            and webhook["delivered_at"] >= 0)):
        raise Invalid("returned", f"webhook must be null or the webhook's state ({', '.join(WEBHOOK_MEMBERS)}: a url, "
                                  f"one of {', '.join(WEBHOOK_STATES)}, a count of attempts), got {webhook!r:.80}")


def _check_job_bounds(progress: dict, result: dict) -> None:
    """progress's bounds: the sums of the lower bounds and costs of the job's items that state
    both (a one-item kind's item: its last stage's), their difference, and the worst item's gap
    beyond abs_gap relative to its cost."""
    kind = _kind(result.get("kind"))
    if hook(kind.verification, "job_outcomes") is not None:
        stages = result.get("stages") if kind.name == "autocalibration" else None
        items = stages[-1:] if isinstance(stages, list) else []
    else:
        items = result.get(kind.item_key) or []
    abs_gap = float(result["certificate"]["options"].get("abs_gap") or 0.0)
    bounded = [(item["cost"], item["lower_bound"]) for item in items
               if isinstance(item, dict) and item.get("cost") is not None and item.get("lower_bound") is not None]
    lower, upper = sum(b for _, b in bounded), sum(c for c, _ in bounded)
    size = sum(abs(c) + abs(b) for c, b in bounded)
    expected = {"lower_bound": lower, "upper_bound": upper, "gap_abs": max(0.0, upper - lower),
                "gap_rel": max((max(0.0, c - b - abs_gap) / c for c, b in bounded if c > 0), default=0.0)}
    for name, value in expected.items():
        if name not in progress:
            continue  # a bound not stated claims nothing
        given = progress[name]
        if not bounded:
            if given is not None:
                raise Invalid("returned", f"progress/{name} is {given!r:.40}: no item of its result states a bound")
            continue
        scale = 1.0 if name == "gap_rel" else size
        if not (isinstance(given, (int, float)) and not isinstance(given, bool)
                and abs(given - value) <= 1e-9 * max(scale, 1e-300)):
            raise Invalid("returned", f"progress/{name} is {given!r:.40}, its result's items give {value!r}")


def _verify(document: Any, returned: dict | None) -> Report:
    report = Report(valid=True)
    tallies = {name: [0, 0] for name in CHECKS}  # passed, failed
    first: dict | None = None

    def fail(check: str, item: int | None, detail: str) -> None:
        nonlocal first
        tallies[check][1] += 1
        if first is None:
            first = {"check": check, "item": item, "detail": detail}

    items: list = []
    options: dict = {}
    hashed: tuple[str, ...] = ()  # the options the problem hash was found to cover
    earlier_estimates = True  # whether its estimates may be of the earlier form (_check_hashes)
    estimates_form = CURRENT_FORM  # the estimates' form it is read in (_check_hashes)
    size = 0
    try:
        # A result holding its certificate is walked once: the certificate nests less deeply.
        holds = returned is not None and returned.get("certificate") is document
        if (not holds and nesting_depth(document, MAX_DEPTH) > MAX_DEPTH) or (
                returned is not None and nesting_depth(returned, MAX_DEPTH) > MAX_DEPTH):
            raise Invalid("format", f"the document nests deeper than {MAX_DEPTH} levels")
        size = document_size(returned if returned is not None else document)
        if returned is not None and not holds:
            size += document_size(document)
        # A member no check reads claims nothing: refused in a certificate on its own, and in one a
        # result carries (a result's own members beside it would be read as the certificate's)
        extra = sorted(str(name) for name in set(document) - CERTIFICATE_MEMBERS)
        if extra and returned is None:
            raise Invalid("format", f"a certificate (it has 'format') has no member {extra[0]!r:.40}: a result "
                                    "carries its certificate in 'certificate'")
        if extra:
            raise Invalid("format", f"certificate has a member {extra[0]!r:.40} no certificate has (its members: "
                                    f"{', '.join(sorted(CERTIFICATE_MEMBERS))})")
        items = _document_items(document)
        tallies["format"][0] += 1
        _check_option_names(document["kind"], document["options"])
        options = checked_options(document["kind"], document["options"])
        tallies["options"][0] += 1
        hashed, earlier_form, earlier_estimates, estimates_form = _check_hashes(document, options)
        tallies["data_hash"][0] += 1
        _check_item_count(document)
        check_data = hook(_adapter(document["kind"]), "check_data")
        if check_data is not None:  # members beyond the kind's, which no check would read
            check_data(document["data"])
        report.scope = scope_statement(document["kind"], options)
        run_control = residual_claims.run_control_scope(document["options"])
        if run_control is not None:  # what the report says of them, the statement being silent
            report.scope["run_control"] = run_control
        data_scope = hook(_adapter(document["kind"]), "data_scope")
        if data_scope is not None:
            report.scope.update(data_scope(document["data"], options, items))
        if earlier_form is not None:
            report.scope["problem_sha256"] = earlier_form
    except Invalid as exc:
        fail(exc.check, None, exc.detail)
        items = []
    except (TypeError, ValueError, RecursionError) as exc:  # e.g. NaN in the data: not canonical JSON
        fail("data_hash", None, f"the data cannot be hashed: {type(exc).__name__}: {exc}")
        items = []
    adapter = _adapter(document["kind"]) if items else None
    # The work the document may ask for, in proportion to its size (strict.charge).
    with work_budget(WORK_PER_UNIT * size + WORK_BASE), reading(estimates_form):
        _verify_all(document, returned, adapter, options, items, report, tallies, fail, hashed, earlier_estimates)
    report.first_failure = first
    # a result may make a certified claim beyond its items, checked by its kind's check_result
    # (a reconstruction's certified K, against its calibration certificate, where no point is placed)
    beyond = (report.scope or {}).get("result_claims_checked") or 0
    report.valid = first is None and (report.items_checked > 0 or beyond > 0)
    if report.discounted and report.scope is not None:
        report.scope["discounted"] = report.discounted
        report.scope["statement"] += ("; except that the items listed in discounted (certificates written before "
                                      "proofs counted their rounding) claim a lower_bound their proofs meet only with "
                                      "rounding uncounted: for them read proven, the bound proven with it counted, for "
                                      "lower_bound (their cost is within the gap tolerance of it)")
    if report.within_abs_gap and report.scope is not None:
        # abs_gap is capped in each kind's units, but a document chooses its coordinates' units
        # (normalised image coordinates make a residual of 1 a radian): where only abs_gap
        # certifies an item, the report says so beside the item.
        report.scope["within_abs_gap"] = report.within_abs_gap
        report.scope["statement"] += (f"; the items listed in within_abs_gap are certified through abs_gap "
                                      f"({options['abs_gap']!r}, in the cost's units), not rel_gap: their gap exceeds "
                                      "rel_gap times their cost, so for them optimal means a cost at most abs_gap "
                                      "above the least cost in the scope")
    if first is None and report.items_checked == 0 and not beyond:
        report.first_failure = {"check": "format", "item": None, "detail": "no certified item to check"}
    report.checks = [{"name": name, "passed": passed, "failed": failed}
                     for name, (passed, failed) in tallies.items() if passed or failed]
    return report


def _verify_all(document: dict, returned: dict | None, adapter, options: dict, items: list, report: Report,
                tallies: dict, fail, hashed: tuple[str, ...] = (), earlier_estimates: bool = True) -> None:
    """_verify's checks of the items, of what ties them together, and of the result returning
    them (failures counted through ``fail``; ``hashed``: the options the problem hash covers;
    ``earlier_estimates``: whether the hash's form lets its estimates be of the earlier form)."""
    forget = hook(adapter, "forget", lambda: None)  # what an adapter remembers of one document
    forget()
    try:
        _verify_items(document, options, items, report, tallies, fail)
    finally:
        forget()
    valid = _clean(tallies)
    together = hook(adapter, "check_claims") if valid and items else None
    if together is not None:  # what ties a kind's claims to each other (e.g. the stages of one solve)
        try:
            together(items, options)
            tallies["claim"][0] += 1
        except Invalid as exc:
            fail(exc.check, None, exc.detail)
    scoped = hook(adapter, "scope_of_items") if _clean(tallies) and items else None
    if scoped is not None and report.scope is not None:  # numbers of the scope each item's proof states
        report.scope.update(scoped(items))
    if returned is not None and _clean(tallies):
        try:
            _check_returned(returned, document, earlier_estimates)
            # What else a kind's result returns on the strength of its certificates (e.g. a
            # reconstruction's cameras, against the camera certificate beside its points').
            check_result = hook(_adapter(document["kind"]), "check_result")
            # The hash's form, as _check_hashes found it: the options it covers.
            scoped = check_result(returned, document, lambda other: _verify(other, None),
                                  hashed=hashed) if check_result else None
            if isinstance(scoped, dict) and report.scope is not None:  # e.g. which labels are tied to the input
                report.scope.update(scoped)
            returned_scope = hook(adapter, "returned_scope")  # e.g. root regions in earlier words
            if returned_scope is not None and report.scope is not None:
                report.scope.update(returned_scope())
            tallies["returned"][0] += 1
        except Invalid as exc:
            fail(exc.check, None, exc.detail)
        except Exception as exc:  # a malformed result is invalid, never a crash
            fail("returned", None, f"{type(exc).__name__}: {exc}")


def _clean(tallies: dict) -> bool:
    """Whether no check has failed yet."""
    return not any(failed for _, failed in tallies.values())


def _verify_items(document: dict, options: dict, items: list, report: Report, tallies: dict, fail) -> None:
    """Every claim of the document checked in turn (failures counted through ``fail``). A kind
    may prove many claims at once (``proven_together``: the positions it proves, every check
    passed); the rest are checked one by one, and a failure is named there."""
    together, proven = hook(_adapter(document["kind"]), "proven_together") if items else None, set()
    if together is not None:
        try:
            proven, checks = together(document["data"], options, items)
        except Exception:  # nothing proven together: each claim is checked alone, and says why
            proven = set()
    for position, claim in enumerate(items):
        if not isinstance(claim, dict) or type(claim.get("index")) is not int or claim["index"] != position:
            fail("format", position, "each item must be an object whose index is its position")
            continue
        certified = claim.get("certified")
        if certified is not True:
            if certified is not False:
                fail("claim", position, "certified must be true or false")
            else:
                try:
                    uncertified_claim(document["kind"], document["data"], options, claim)
                except Invalid as exc:
                    fail(exc.check, position, exc.detail)
                except Exception as exc:  # a malformed document is invalid, never a crash
                    fail("format", position, f"{type(exc).__name__}: {exc}")
            report.items_skipped += 1
            continue
        report.items_checked += 1
        if position in proven:
            for name in checks:
                tallies[name][0] += 1
            _note_abs_gap(document["kind"], options, claim, position, report)
            continue
        try:
            arrays = _adapter(document["kind"]).read(document["data"], claim["index"])
            names, bound, discounted = _verify_claim(document["kind"], arrays, options, claim, True)
            for name in ["data"] + names:
                tallies[name][0] += 1
            if discounted:
                report.discounted.append({"item": position, "lower_bound": claim["lower_bound"], "proven": bound})
            _note_abs_gap(document["kind"], options, claim, position, report)
        except Invalid as exc:
            fail(exc.check, position, exc.detail)
        except Exception as exc:  # a malformed document is invalid, never a crash
            fail("format", position, f"{type(exc).__name__}: {exc}")


def _note_abs_gap(kind: str, options: dict, claim: dict, position: int, report: Report) -> None:
    """A certified claim whose gap rel_gap alone does not allow (its proof met only abs_gap):
    named in the report's scope (within_abs_gap)."""
    rel_gap_of = hook(_adapter(kind), "rel_gap_of", lambda options_, _: options_["rel_gap"])
    if float(claim["gap"]) > float(rel_gap_of(options, position)) * abs(float(claim["cost"])):
        report.within_abs_gap.append(position)


def _check_item_count(document: dict) -> None:
    """The certificate's items are the data's, one each (index = position): a result cannot leave
    out the items it did not certify (the hashes cover the data, not the items)."""
    key = hook(_adapter(document["kind"]), "data_items")
    if key is None:  # a kind whose items are its stages (autocalibration: check_claims counts them)
        return
    entries = document["data"].get(key) if isinstance(document["data"], dict) else None
    if not isinstance(entries, list):
        raise Invalid("data", f"data/{key} must be a list")
    expected = len(entries)
    if len(document["items"]) != expected:
        raise Invalid("format", f"the certificate has {len(document['items'])} items, its data {expected}: one item "
                                "for each item of the data")


# An uncertified item's status (docs/certificate.md, "Uncertified items"): how its search stopped
# (node_limit, time_limit, cancelled) or not_certified, words that claim nothing about the data
# (a kind may add its own such words: its adapter's uncertified_statuses); "infeasible" only
# where the verifier proves it from the data (the kind's proves_infeasible).
UNCERTIFIED_STATUSES = ("not_certified", "node_limit", "time_limit", "cancelled")


def uncertified_claim(kind: str, data: dict, options: dict, claim: dict) -> None:
    """An item not certified states only figures the verifier checks without a proof: its status
    is one of UNCERTIFIED_STATUSES, or "infeasible" where the verifier proves it from the data
    (then with no solution); its cost is what its solution costs on the data (none when it
    returns no solution); and it states no lower_bound and no gap, since no proof the verifier
    checks backs them (a bound at most the optimum's cost cannot be told from a larger one
    without one)."""
    status = claim.get("status")
    if status == "infeasible":
        proves = hook(_adapter(kind), "proves_infeasible")
        if proves is None or not proves(data, claim, options):
            raise Invalid("claim", "status 'infeasible' is said only where the verifier proves it from the data (a "
                                   "track with a view whose depth is a non-positive constant); this item's is not")
    elif status not in (words := hook(_adapter(kind), "uncertified_statuses", UNCERTIFIED_STATUSES)):
        raise Invalid("claim", f"an uncertified item's status is one of {', '.join(words)} (or 'infeasible' where "
                               f"the data prove it), not {status!r:.40}")
    for name in ("lower_bound", "gap"):
        if claim.get(name) is not None:
            raise Invalid("claim", f"{name} is {claim[name]!r:.40}: an uncertified item states none (no proof the "
                                   "verifier checks backs it)")
    cost = claim.get("cost")
    solution_cost = hook(_adapter(kind), "solution_cost")
    true = solution_cost(data, claim, options) if solution_cost is not None else None
    if true is None:
        if cost is not None:
            raise Invalid("objective", f"cost {cost!r:.40} is stated, and no solution is returned to cost it")
        return
    if status == "failed":
        raise Invalid("claim", "status 'failed' says no solution was found, and this item returns one")
    if cost is None:
        return  # a solution returned without its cost says less
    value, allowance = true
    if not (isinstance(cost, (int, float)) and not isinstance(cost, bool) and abs(cost - value) <= allowance):
        raise Invalid("objective", f"cost {cost!r:.40}, its solution costs {value!r}")


def _document_items(document: Any) -> list[dict]:
    if not isinstance(document, dict) or document.get("format") != FORMAT:
        raise Invalid("format", f"not a {FORMAT} document")
    # an integer (strict.same_counts): 2.0 == 2 in Python, and a count stated as a float verified (review 62)
    if not same_counts(document.get("version"), VERSION):
        raise Invalid("format", f"version {document.get('version')!r} is not {VERSION}")
    for key in ("kind", "data", "options", "items", "data_sha256", "problem_sha256"):
        if key not in document:
            raise Invalid("format", f"missing {key!r}")
    kind = _kind(document["kind"])
    if not isinstance(document["items"], list):
        raise Invalid("format", "items must be a list")
    _check_claim_members(kind, document["items"])
    return document["items"]


def _check_claim_members(kind, items: list) -> None:
    """Each item of a certificate holds only what certificate_document writes of a claim
    (records.CLAIM_MEMBERS) and its kind's solution fields: a member no check reads (an item's
    "unique_optimum") claims nothing, so it is refused, on every path an item is checked by."""
    from geocert.core.records import CLAIM_MEMBERS

    allowed = set(CLAIM_MEMBERS) | set(kind.solution_fields)
    for index, item in enumerate(items):
        extra = sorted(str(name) for name in set(item) - allowed) if isinstance(item, dict) else []
        if extra:
            raise Invalid("format", f"items/{index} has a member {extra[0]!r:.40} no {kind.name} claim has (its "
                                    f"members: {', '.join(sorted(allowed))}); a member no check reads claims "
                                    "nothing, so it is refused")


def _problem_form(document: dict, options: dict, names: tuple[str, ...], marks: dict | None, values: bool,
                  digest) -> tuple[tuple[str, ...], str | None, bool, int] | None:
    """_check_hashes' answer where the problem hash is of one of the forms a kind's documents take
    (with the data hashed as ``values`` says, ``digest`` their text's): today's, one of the
    estimates' earlier marks (determinacy.FORMS), one without the kind's mark, an earlier options
    form; None where it is none of them."""
    kind, data = document["kind"], document["data"]
    if problem_hash(kind, data, options, names, marks, values, digest) == document["problem_sha256"]:
        return names, None, not marks, CURRENT_FORM
    if marks == ESTIMATES_FORM:  # the estimates' earlier marked forms, newest first
        for number in range(CURRENT_FORM - 1, 0, -1):
            marked = problem_hash(kind, data, options, names, FORMS[number - 1], values, digest)
            if marked == document["problem_sha256"]:
                return names, _earlier_mark(FORMS[number - 1], number), False, number
    if marks and problem_hash(kind, data, options, names, values=values, digest=digest) \
            == document["problem_sha256"]:
        return names, _unmarked_form(names, marks), True, 0
    # a kind whose hash came to cover more options: its earlier forms, newest first, each with
    # what the report's scope says of it
    for earlier, statement in hook(_adapter(kind), "earlier_forms"):
        if problem_hash(kind, data, options, earlier, values=values, digest=digest) == document["problem_sha256"]:
            return earlier, statement(options), True, 0
    return None


def _check_hashes(document: dict, options: dict) -> tuple[tuple[str, ...], str | None, bool, int]:
    """The data's and the problem's hashes; returns the options the problem hash covers, what
    the report's scope says of a problem hash of a kind's earlier form (None for the current one),
    whether the document's determinacy estimates may be of the earlier form (intervals stating
    no tolerance: a kind that declares no mark, or a hash without the mark its kind declares), and
    the number of the estimates' form the document is read in (determinacy.reading: 0 unmarked)."""
    # Today's hashes are of the numbers' values (certificates.hashed_numbers); a document written
    # before hashed them with an integer no float holds kept exact, or, before that, Python's text
    # of them. Each form whose data hash is the document's is tried for the problem hash: where the
    # data's text is the same in two forms (no integer, no negative zero), the options' may not
    # be (review 48: "focal": [400, 4000] hashed as Python wrote it).
    data, kind = document["data"], document["kind"]
    adapter = _adapter(kind)
    names = hook(adapter, "claim_options", CLAIM_OPTIONS)
    marks = hook(adapter, "hash_marks")
    expected = None
    for values, exact_integers in ((True, False), (True, True), (False, False)):
        digest = data_digest(data, values, exact_integers)  # written once for every hash of the form
        hashed = data_hash(kind, data, values, digest)
        expected = expected or hashed
        if hashed != document["data_sha256"]:
            continue
        found = _problem_form(document, options, names, marks, values, digest)
        if found is not None:
            return found
        expected_problem = problem_hash(kind, data, options, names, marks, values, digest)
        break
    else:
        raise Invalid("data_hash", f"data_sha256 is {document['data_sha256']!r}, but the data hash to {expected!r}")
    # the data's text the same in the values' form and as written: the options as written
    if values and data_hash(kind, data, False) == document["data_sha256"]:
        found = _problem_form(document, options, names, marks, False, data_digest(data, False))
        if found is not None:
            return found
    raise Invalid("data_hash", f"problem_sha256 is {document['problem_sha256']!r}, but the kind, data and options "
                               f"({', '.join(names)}) hash to {expected_problem!r}")


def _unmarked_form(names: tuple[str, ...], marks: dict) -> str:
    """What the report's scope says of a document hashed without the form its kind declares
    (Verification.hash_marks: the estimates' form, determinacy.ESTIMATES_FORM): every rule of the
    estimates' forms it is not held to (determinacy.lacked)."""
    return (f"the earlier form: it covers the kind, the data and {', '.join(names)}, not the form today's documents "
            f"declare ({marks!r}). Compare it with your request: a document of this form was written before "
            "every determinacy interval stated its tolerance, so an estimate whose intervals state none is read as "
            "such a document's, its determined meaning every interval bounded (not within a tenth of its "
            f"quantity's scale). {_lacked(0)}")


def _earlier_mark(marks: dict, number: int) -> str:
    """What the report's scope says of a document hashed with the mark of the estimates' earlier
    form ``number`` (determinacy.FORMS): its estimates are recomputed in that form, and every rule
    that form lacks is named (determinacy.lacked)."""
    return (f"an earlier form of the estimates ({marks!r}), not today's ({ESTIMATES_FORM!r}): its determinacy "
            f"estimates are read as that form wrote them. {_lacked(number)}")


def _lacked(number: int) -> str:
    rules = lacked(number)
    return ("Today's rules this form is not held to, so that a document restated in it may claim what today's "
            "would refuse: " + "; ".join(f"({k}) {words}" for k, words in enumerate(rules, 1)) + ".") if rules else ""


# What a result returns of each item, which must equal what its certificate proves (and the
# kind's solution fields).
RETURNED_FIELDS = ("status", "certified", "cost", "lower_bound", "gap")


def check_members(kind, result: dict) -> None:
    """A result holds only the members its kind writes, and so does each object it nests one level
    down (its items, cameras, stats: VerifiedKind.members). A member no check reads is not a place
    to hide what a reader might take for part of the proof (a top-level ``certified``, an item's
    ``verified``, a list of items of another kind), as strict.record refuses one in a proof."""
    for where, names in kind.members:
        value = result if where == "" else result.get(where)
        for index, entry in enumerate(value if isinstance(value, list) else [value]):
            extra = sorted(str(name) for name in set(entry) - set(names)) if isinstance(entry, dict) else []
            if extra:
                place = "the result" if where == "" else f"{where}/{index}" if isinstance(value, list) else where
                raise Invalid("returned", f"{place} has a member {extra[0]!r:.40} no {kind.name} result writes "
                                          f"(its members: {', '.join(names)}); a member no check reads claims "
                                          "nothing, so it is refused")
    # and every record nested below those, at any depth (core.records: the writers' members)
    from geocert.core import records
    from geocert.verify.adapters import NESTED_RECORDS

    records.check_nested(result, NESTED_RECORDS.get(kind.name, ()))
    if kind.name == "reconstruction":  # its stages, each closed to its writer's members by its name
        from geocert.verify.reconstruction_stages import STAGE_RECORDS

        records.check(result.get("stages"), STAGE_RECORDS, "stages")
    check_complete(kind, result)


# The members each kind's writer always writes (null where it has nothing to state): a record
# closed to its writer's members (check_members) is also complete to them, so that leaving one out
# cannot switch off the check that reads it or make a record say what its writer never would (a
# certified item without the summary of what its proof covers, stats without the counts). From
# the writers: geocert.kinds' result models and assemble (fractional, bilinear: every field of the
# item and stats models), autocalibration's stratified_item and direct item (every headline field
# written, null before a stage finds it; ``Ks`` only with varying focal lengths, ``status`` and
# ``reason`` not by the earlier form's writer), core.certificates' summaries. Every format-2
# document stored in tests/data/certificates has them. A reconstruction's result and stats are
# complete here (kinds.reconstruction: run's item, assemble), and its summary's times
# (claims.summarise: each stage's elapsed_s and cpu_s, written since before any stored form), its
# cameras, points and stage records by its own checks (verify.reconstruction*: CAMERA_WRITTEN,
# reconstruction_stages._written), its summary's calibration model by _check_calibration.
_ITEM = ("cost", "lower_bound", "gap", "status", "certified", "nodes", "elapsed_s", "reason")
_STATS = ("items", "certified", "nodes", "solve_s", "elapsed_s", "statuses")
_MAP = (("", ("kind", "norm", "maps", "stats")), ("maps", _ITEM + ("matrix", "residuals")), ("stats", _STATS))
COMPLETE: dict[str, tuple[tuple[str, tuple[str, ...]], ...]] = {
    "triangulation": (("", ("kind", "norm", "tracks", "stats")), ("tracks", _ITEM + ("point", "at_infinity")),
                      ("stats", _STATS)),
    "resection": _MAP,
    "homography": _MAP,
    "bilinear": (("", ("kind", "norm", "coefficients", "frames", "stats")),
                 ("frames", _ITEM + ("camera", "coefficients", "shape", "residuals", "baseline")), ("stats", _STATS)),
    "autocalibration": (("", ("kind", "method", "intrinsics", "plane_at_infinity", "K", "dual_absolute_quadric",
                              "upgrade", "cameras", "points", "baseline", "stages", "stats")),
                        ("stages", _ITEM + ("name",)), ("stats", _STATS)),
    # its items' other members (cameras, points) and stage records by its own checks (verify.
    # reconstruction*); a point's ``certified`` here, so that a certified point's summary states
    # what a triangulation track's does (the same writer, track_document: review 49)
    "reconstruction": (("", ("kind", "norm", "cameras", "points", "stages", "summary", "images", "stats")),
                       ("points", ("certified",)), ("summary", ("time_s", "cpu_s")), ("stats", _STATS)),
}
# An item's ``certificate`` (its summary) is required where it is certified (below); an
# autocalibration stage's too unless it never started (kinds.autocalibration.cancelled_item writes
# the outcome alone), with its ``plane_at_infinity`` (stratified), and its ``determinacy`` wherever it
# states a cost (the writer analyses every stage that found a plane or a K).
# What a certified item's certificate summary states of its proof (core.certificates.summary):
# the scope covered, the tolerance met, and for a branch and bound over a region its root region
# and leaves (an autocalibration stage's summary states no region: its proof is one program's).
SUMMARY = ("scope", "tolerance", "tolerance_met")
REGION_SUMMARY = SUMMARY + ("root_region", "leaves")


def check_complete(kind, result: dict) -> None:
    """Every record of a result states each member its writer writes (COMPLETE; a certified
    item's summary: SUMMARY or REGION_SUMMARY); the failure names the first one left out."""
    required = COMPLETE.get(kind.name)
    if required is None:
        return
    for where, names in required:
        value = result if where == "" else result.get(where)
        for index, entry in enumerate(value if isinstance(value, list) else [value]):
            if not isinstance(entry, dict):
                continue  # typed by the checks that read it
            place = "the result" if where == "" else f"{where}/{index}" if isinstance(value, list) else where
            _require(entry, names, place, kind.name)
            if kind.name == "autocalibration" and where == "stages":
                _require(entry, _stage_members(entry, result), place, kind.name)
            summary = entry.get("certificate") if where == kind.item_key else None
            if where == kind.item_key and entry.get("certified") is True:
                # null only where the job asked for the brief detail (options.detail: no summary, no estimate)
                _require(entry, ("certificate",), place, kind.name)
                if not isinstance(summary, dict):
                    continue
                _require(summary, SUMMARY if kind.name == "autocalibration" else REGION_SUMMARY,
                         f"{place}/certificate", kind.name)


def _stage_members(stage: dict, result: dict) -> tuple[str, ...]:
    """What an autocalibration stage states beyond its outcome (COMPLETE's note)."""
    never_started = stage.get("status") in ("cancelled", "time_limit") and not stage.get("nodes") \
        and stage.get("cost") is None
    names = () if never_started else ("certificate",) + (() if result.get("method") == "direct"
                                                         else ("plane_at_infinity",))
    return names + (("determinacy",) if is_number(stage.get("cost")) else ())


def _require(entry: dict, names: tuple[str, ...], place: str, kind: str) -> None:
    missing = [name for name in names if name not in entry]
    if missing:
        raise Invalid("returned", f"{place} leaves out its member {missing[0]!r}, which every {kind} result's writer "
                                  "states (null where it has nothing to state): a record missing a member is not "
                                  "its writer's")


def _check_returned(result: dict, certificate: dict, earlier_estimates: bool = True) -> None:
    """The result is what its certificate proves, and its other fields are tied to the claims
    (``earlier_estimates``: whether the document's hash lets its estimates be of the earlier form,
    their intervals stating no tolerance: _check_hashes)."""
    kind = _kind(certificate["kind"])
    key = kind.item_key
    check_members(kind, result)
    if result.get("kind") != certificate["kind"] or result.get("norm") != certificate["options"].get("norm"):
        raise Invalid("returned", "the result's kind or norm differs from its certificate's")
    items = result.get(key)
    if not isinstance(items, list) or len(items) != len(certificate["items"]):
        raise Invalid("returned", f"the result's {key} are not the certificate's items")
    for index, (item, claim) in enumerate(zip(items, certificate["items"])):
        if not isinstance(item, dict):
            raise Invalid("returned", f"{key}/{index} must be an object")
        for name in RETURNED_FIELDS + tuple(kind.solution_fields):
            if (name in item or name in claim) and not same(item.get(name), claim.get(name)):
                raise Invalid("returned", f"{key}/{index}/{name} is {item.get(name)!r}, its certificate proves "
                                          f"{claim.get(name)!r}")
        _check_item_notes(item, f"{key}/{index}")
        if key in REASONLESS_WHEN_CERTIFIED and item.get("certified") is True and item.get("reason") is not None:
            raise Invalid("returned", f"{key}/{index}/reason is {item['reason']!r:.80} beside certified true: its "
                                      "writer states a reason only for an item it does not certify (why not)")
    stats = result.get("stats")
    if isinstance(stats, dict):
        _check_item_notes({"nodes": stats.get("nodes")}, "stats")
    check_notes(result)  # its informational fields, typed
    own = hook(kind.verification, "check_returned")
    if own is not None:  # what else the result returns, derived from the claims
        own(result, certificate, earlier_estimates)
    estimates.check(kind, result, certificate, earlier_estimates)  # a track's or map's determinacy, recomputed
    if certificate["kind"] not in ("triangulation", "resection"):  # kinds whose determinacy proves intervals (own check)
        # a kind proving some intervals says which parts are estimates still (its check_returned checked the rest)
        estimates_of = hook(kind.verification, "estimates_of")
        _check_estimates(result if estimates_of is None else estimates_of(result, certificate),
                         earlier=earlier_estimates)
    _check_summaries(kind, result, certificate)
    _check_stats(kind, result)


def _check_estimates(value: Any, where: str = "", earlier: bool = True) -> None:
    """Every ``determinacy`` a result holds outside its certificate is an estimate: none may call
    itself proven, or state proven intervals (``proven_intervals``, or ``proven_over_planes``: a
    stratified metric stage's, which its adapter's estimates_of removes where its proof carries
    them), where no proof of them is carried (review 51: intervals stated as proven over planes
    beside a track's, a map's, a frame's or any stage's estimate verified)."""
    if isinstance(value, dict):
        for name, item in value.items():
            if name in ("certificate", "camera_certificate", "calibration_certificate"):
                continue
            if name == "determinacy" and isinstance(item, dict) and (
                    not (item.get("proven") is None or item.get("proven") is False)  # 0 == False: not a boolean
                    or item.get("proven_intervals") is not None or item.get("proven_over_planes") is not None):
                raise Invalid("returned", f"{where}/determinacy says proven, and no proof of its intervals is "
                                          "carried (an estimate is proven: false)")
            if name == "determinacy" and isinstance(item, dict):
                estimates.check_determined(item, f"{where}/determinacy", earlier)
            _check_estimates(item, f"{where}/{name}", earlier)
    elif isinstance(value, list):
        for index, item in enumerate(value):
            _check_estimates(item, f"{where}/{index}", earlier)


def _check_stats(kind, result: dict) -> None:
    """The job's counts (``stats``: items, certified, statuses) are the items'. A kind whose job
    is one item proving several claims (autocalibration's stages, a reconstruction's points)
    says what that item's outcome is (its adapter's job_outcomes)."""
    stats = result.get("stats")
    if stats is None:
        return
    own = hook(kind.verification, "job_outcomes")
    outcomes = own(result) if own is not None else [
        (item.get("status"), item.get("certified") is True) for item in result.get(kind.item_key) or []
        if isinstance(item, dict)]
    if not isinstance(stats, dict):
        raise Invalid("returned", "stats must be an object")
    for name in ("solve_s", "elapsed_s"):  # durations (informational), each a number >= 0 when stated
        if stats.get(name) is not None and not (is_number(stats[name]) and stats[name] >= 0):
            raise Invalid("returned", f"stats/{name} must be null or a number of seconds >= 0, got "
                                      f"{stats[name]!r:.40}")
    expected = {"items": len(outcomes), "certified": sum(certified for _, certified in outcomes)}
    # The job's nodes are its items' (runner.item_sums; a kind whose job is one item counts that
    # item's nodes as the sum over its stages or points, which are the items read here: the
    # stratified autocalibration's affine and metric stages, a reconstruction's points), each a
    # count (_check_item_notes). An item stating none (null) leaves the sum unstated.
    nodes = [item.get("nodes") for item in result.get(kind.item_key) or [] if isinstance(item, dict)]
    if all(type(n) is int for n in nodes):
        expected["nodes"] = sum(nodes)
    elif stats.get("nodes") is not None:
        raise Invalid("returned", f"stats/nodes is {stats['nodes']!r:.40}, and an item states no nodes to sum")
    statuses = {}
    for status, _ in outcomes:
        if status is not None:
            statuses[status] = statuses.get(status, 0) + 1
    if own is None or all(status is not None for status, _ in outcomes):
        expected["statuses"] = statuses
    elif "statuses" in stats and not (isinstance(stats["statuses"], dict) and all(
            isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in stats["statuses"].values())
            and sum(stats["statuses"].values()) <= len(outcomes)):  # the job's own status, unread, counts one item
        raise Invalid("returned", f"stats/statuses {stats['statuses']!r:.80} counts more than the job's "
                                  f"{len(outcomes)} item(s)")
    for name, value in expected.items():
        if name in stats and not same_counts(stats[name], value):  # counts: integers (12.0 is none)
            raise Invalid("returned", f"stats/{name} is {stats[name]!r}, the items give {value!r}")


# The largest count a result states: 2^53 - 1, the largest integer every JSON reader holds exactly
# (RFC 8259, section 6: readers commonly read numbers as IEEE 754 doubles). No search reaches it
# (max_nodes is at most 1,000,000 an item); a Python reader would take 10**400 as it is written.
MAX_COUNT = 2 ** 53 - 1


# The items whose writers state a reason only where they do not certify (fractional.triangulation
# and maps: refused_by_verifier's None, or the status's reason; bilinear.search: None when
# certified): a certified track's "not certified: the search stopped; this point is not optimal"
# verified (review 64 class 4), words a reader takes as the item's outcome.
REASONLESS_WHEN_CERTIFIED = ("tracks", "maps", "frames")


def _check_item_notes(item: dict, where: str) -> None:
    """An item's informational fields are of their types (docs/certificate.md): ``nodes`` a
    count, ``reason`` words, ``elapsed_s`` a duration; each may be null."""
    nodes, reason, elapsed = item.get("nodes"), item.get("reason"), item.get("elapsed_s")
    if nodes is not None and not (type(nodes) is int and 0 <= nodes <= MAX_COUNT):
        raise Invalid("returned", f"{where}/nodes must be null or a count (an integer from 0 to {MAX_COUNT}), got "
                                  f"{nodes!r:.40}")
    if reason is not None and not isinstance(reason, str):
        raise Invalid("returned", f"{where}/reason must be null or a string, got {reason!r:.40}")
    if elapsed is not None and not (is_number(elapsed) and elapsed >= 0):
        raise Invalid("returned", f"{where}/elapsed_s must be null or a number >= 0, got {elapsed!r:.40}")


# A summary's fields that explain a result but prove nothing (docs/certificate.md), each of a type.
SUMMARY_NOTES = {"scope": "text", "note": "text", "order": "integer", "moment_rank": "integer",
                 "eigenvalue_ratio": "number"}


def _check_summaries(kind, result: dict, certificate: dict) -> None:
    """An uncertified item's certificate summary, when it has one, says its tolerance was not met.
    A certified item's certificate summary (its ``certificate`` member) says what its proof
    does: its tolerance is max(abs_gap, rel_gap * cost) with the item's rel_gap, met, and its
    leaves are the proof's. (Its root_region describes the proof's root box in the caller's
    terms: informational, but for a bilinear frame, where it is the scope: bilinear.verification, and a
    certified map or track, where it is its proof's: fractional.MapItems, fractional.TrackItems.)"""
    items = result.get(kind.item_key)
    if kind.name == "autocalibration":
        items = result.get("stages")
    if not isinstance(items, list):
        return
    options = certificate["options"]
    rel_gap_of = hook(kind.verification, "rel_gap_of", lambda options, index: options.get("rel_gap"))
    for index, (item, claim) in enumerate(zip(items, certificate["items"])):
        summary = item.get("certificate") if isinstance(item, dict) else None
        where = f"{kind.item_key}/{index}/certificate"
        if isinstance(summary, dict):
            # an uncertified item's proof is not checked (uncertified_claim), so its words are none
            _check_note(summary.get("note"), claim.get("proof") if claim.get("certified") is True else None, where)
        if isinstance(summary, dict) and claim.get("certified") is not True:
            if "tolerance_met" in summary and summary["tolerance_met"] is not False:
                raise Invalid("returned", f"{where}/tolerance_met must be false for an uncertified item")
            continue
        if not isinstance(summary, dict):
            continue
        for name, what in SUMMARY_NOTES.items():  # what explains a result but proves nothing: typed
            if name in summary:
                informational(summary[name], f"{where}/{name}", what)
        proof = claim.get("proof") if isinstance(claim.get("proof"), dict) else {}
        if "tolerance" in summary and not (proof.get("type") == "trivial" and summary["tolerance"] == 0.0):
            # (A trivial proof's summary states 0: the bound 0 met without a search.)
            expected = max(float(options.get("abs_gap")), float(rel_gap_of(options, index)) * abs(float(claim["cost"])))
            given = summary["tolerance"]
            # The solver's working tolerance, from its incumbent's cost in the program (the same
            # number but for its rounding: 1.4e-9 apart for a map 1e6 from the origin).
            if not (isinstance(given, (int, float)) and not isinstance(given, bool)
                    and abs(given - expected) <= 1e-6 * expected):
                raise Invalid("returned", f"{where}/tolerance is {given!r}, the options give {expected!r}")
        if "tolerance_met" in summary and summary["tolerance_met"] is not True:
            raise Invalid("returned", f"{where}/tolerance_met must be true for a certified item")
        if "leaves" in summary:
            leaves = proof.get("leaves")
            expected = len(leaves) if isinstance(leaves, list) else 0
            if not same_counts(summary["leaves"], expected):  # a count: 4.0 is not 4 (review 62)
                raise Invalid("returned", f"{where}/leaves is {summary['leaves']!r}, its proof has {expected}")


# A summary's note says how its item's bound was proven, in its writer's words, which are a function
# of the proof (core.summary_notes.note_of: the trivial bound's, the convexity bound's with
# its radius, the sublevel bound's with its radius and rounds; a search states none). The note is
# informational, but words about the proof are the proof's: any other text is refused (a convexity
# radius 6.2 restated 1e6, review 40; the trivial bound's note on a searched frame costing 1.6, and
# "every other map costs at least twice as much" on a map, review 42). A note may be left out (null).


def _check_note(note: Any, proof: Any, where: str) -> None:
    """``proof``: a certified item's (checked), None for an item not certified (it proves nothing,
    so its summary states no note: review 44 had an uncertified track state the trivial bound's
    note beside an unchecked trivial proof)."""
    expected = summary_notes.note_of(proof)
    if note is not None and note != expected:
        raise Invalid("returned", f"{where}/note is {note!r:.120}; its proof's words are "
                                  f"{'none (a search, or an item not certified, states no note)' if expected is None else repr(expected)}")


def verify_item(kind: str, data: dict, options: dict, claim: dict) -> list[str]:
    """Every check of one certified item, in order; raises Invalid at the first failure and
    returns the names of the checks passed."""
    arrays = _adapter(kind).read(data, claim["index"])
    return ["data"] + verify_arrays(kind, arrays, options, claim)[0]


def verify_arrays(kind: str, arrays: tuple, options: dict, claim: dict) -> tuple[list[str], float]:
    """verify_item on one item's raw arrays: (cameras of the views, points) for triangulation,
    (source, target) for maps. Also returns the lower bound the proof establishes (caller's
    units). Strict: the proof must establish lower_bound (a solver checking its own claim)."""
    passed, bound, _ = _verify_claim(kind, arrays, options, claim, False)
    return passed, bound


# A stored certificate written before the proofs counted their rounding (cones.rounding_margin)
# claims the bound its proof gives without it. Measured on the stored certificates: a direct
# autocalibration stage (its dual's entries 1e6 times its bound) then falls 4.5e-6 of its bound
# short of its claim, a metric stage 1e-7. Such a claim is accepted when the proof meets it with
# rounding uncounted (as the certificate was written) and its cost is within its gap tolerance of
# the bound proven with it counted; the report names it (Report.discounted, with that bound).


def _verify_claim(kind: str, arrays: tuple, options: dict, claim: dict, discount: bool
                  ) -> tuple[list[str], float, bool]:
    """Every check of one certified claim: the checks passed, the bound proven, and whether
    lower_bound was read as that bound (``discount``: as DISCOUNT_SHARE allows)."""
    options = checked_options(kind, options)
    adapter = _adapter(kind)
    passed: list[str] = []
    if claim.get("status") != "optimal" or claim.get("certified") is not True:
        raise Invalid("claim", "a certified item has status 'optimal' and certified true")
    claimed = _number(claim.get("cost"), "cost", "claim")
    gap = _number(claim.get("gap"), "gap", "claim")
    lower_claimed = _number(claim.get("lower_bound"), "lower_bound", "claim")
    if not (0 <= gap and lower_claimed <= claimed
            and abs((claimed - gap) - lower_claimed) <= 1e-12 * max(abs(claimed), abs(lower_claimed))):
        raise Invalid("claim", f"lower_bound {lower_claimed!r}, cost {claimed!r} and gap {gap!r} disagree "
                               "(lower_bound = cost - gap, gap >= 0)")
    passed.append("claim")
    own = hook(adapter, "check_claim")
    if own is not None:  # the kind checks its solution, scope and proof itself, and names its tolerance
        bound, rel_gap = own(arrays, options, claim, claimed, lower_claimed, passed)
    else:
        bound = _check_residual_claim(kind, adapter, arrays, options, claim, claimed, lower_claimed, passed)
        rel_gap = options["rel_gap"]
    tolerance = max(options["abs_gap"], rel_gap * abs(claimed))
    discounted = False
    if not bound >= lower_claimed - BOUND_TOLERANCE * abs(lower_claimed):
        discounted = discount and claimed - bound <= tolerance * (1 + 1e-12) and _met_uncounted(kind, arrays, options,
                                                                                                 claim)
        if not discounted:
            raise Invalid("lower_bound", f"the proof establishes {bound!r}, less than lower_bound {lower_claimed!r}")
    passed.append("lower_bound")
    if not gap <= tolerance * (1 + 1e-12):
        raise Invalid("gap", f"gap {gap!r} exceeds the tolerance {tolerance!r} (abs_gap, rel_gap)")
    passed.append("gap")
    return passed, bound, discounted


def _check_residual_claim(kind: str, adapter, arrays: tuple, options: dict, claim: dict, claimed: float,
                          lower_claimed: float, passed: list[str]) -> float:
    """A fractional kind's claim: its solution's cost and scope from the raw residuals, and the
    bound its proof establishes."""
    norm = options["norm"]
    item = adapter.item(arrays, norm)
    solution = item.solution(claim)
    residuals, depths, rounding = item.raw_residuals(solution)
    if not item.depths_agree(depths):
        raise Invalid("objective", "the solution puts a point at non-positive depth")
    cost = norm_cost(residuals, norm)
    slack = cost_rounding(residuals, rounding, norm)
    # An item that can say how far its data determine each residual (tracks and maps do; a kind
    # added later need not) must have a cost the data determine to within the tolerance (below).
    uncertainty = getattr(item, "residual_uncertainty", None)
    determined = None if uncertainty is None else uncertainty(solution)
    spread = 0.0 if determined is None else cost_rounding(residuals, determined, norm)
    exact_of = getattr(item, "exact_residuals", None)
    if exact_of is not None and determined is not None and exact.needs_exact(residuals, determined, cost, norm,
                                                                             OBJECTIVE_TOLERANCE):
        # Far-off data: this machine's floats may lie the spread from the exact residuals, and a
        # claim held to a window that wide understated a far resection's cost fourfold (review 37).
        # The writer states the cost of the residuals computed exactly (core.exact), one number
        # on every machine, and is held to it.
        residuals = exact_of(solution)
        cost = exact.cost(residuals, norm)
        slack = exact.slack(residuals, norm)
    if not abs(cost - claimed) <= OBJECTIVE_TOLERANCE * abs(cost) + slack:
        raise Invalid("objective", f"the solution costs {cost!r}, the certificate claims {claimed!r}")
    tolerance = max(options["abs_gap"], options["rel_gap"] * abs(claimed))
    # The gap from the cost the data give (and its rounding), not the claimed one: a claim may
    # round its cost, never its gap.
    if not (cost + slack) - lower_claimed <= tolerance * (1 + 1e-12):
        raise Invalid("gap", f"the solution costs {cost!r} (to within {slack!r}), more than the tolerance "
                             f"{tolerance!r} above lower_bound {lower_claimed!r}")
    if not spread <= tolerance:
        raise Invalid("objective", f"the data determine the solution's cost only to within {spread!r}, more than "
                                   f"the tolerance {tolerance!r} (a point nearly on a principal plane, or data far "
                                   "from the origin)")
    passed.append("objective")
    if options["max_residual"] is not None:
        longest = float(np.max(residual_lengths(residuals)))
        if not longest <= options["max_residual"]:
            raise Invalid("scope", f"the solution has a residual of length {longest!r}, beyond max_residual "
                                   f"{options['max_residual']!r}")
    passed.append("scope")
    proof = claim.get("proof")
    if not isinstance(proof, dict):
        raise Invalid("format", "a certified item needs a proof")
    if proof.get("type") == "trivial":  # every cost is a sum of norms, so 0 bounds it
        record(proof, "proof", ("type",))
        bound = 0.0
    elif proof.get("type") in adapter.proofs:
        bound = adapter.proofs[proof["type"]](item, options, proof, lower_claimed, solution, passed)
    else:
        raise Invalid("format", f"proof type {proof.get('type')!r} is not one {kind} takes")
    return bound


def _met_uncounted(kind: str, arrays: tuple, options: dict, claim: dict) -> bool:
    """Whether the claim's proof meets its lower bound with rounding uncounted (as a certificate
    written before it was counted computed it)."""
    with rounding_uncounted():
        try:
            _verify_claim(kind, arrays, options, claim, False)
        except Invalid:
            return False
    return True


def _self_check(kind: str, arrays: tuple, options: dict, claim: dict) -> None:
    """The solvers' self-check (core.self_check, GEOCERT_SELF_VERIFY=1): the claim verified."""
    try:
        verify_arrays(kind, arrays, options, claim)
    except Invalid as exc:
        raise SelfCheckFailed(f"{kind}: check {exc.check} failed: {exc.detail}") from exc


self_check.install(_self_check)
