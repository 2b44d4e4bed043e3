"""Review 52: the two holes review 51 left (a reconstruction's calibration model, the pooled
floor's quantiles unpaid), and a hostile review of the newest checks (review 51's fixes, and
every result field of the stored documents): one edit at a time of each member (numbers scaled,
nudged by 1e-6, set to -0.0, a subnormal, 1e308, "NaN", a string, null; booleans flipped;
strings emptied; lists emptied, cut, repeated, reversed, null appended; members deleted or
added), each kind's members stated in every other kind's result, options restated with their
hashes made again, items and members reordered, one kind's certificate carried in another's place.

Review 51's holes (a test below for each, which failed while it stood):

- summary.calibration.model restated "varying" beside cameras sharing one K (the adjustment's
  model simple) verified. Fixed: reconstruction._calibration_models, the writer's model from the
  adjustment's record (claims.calibration_claim: varying exactly when it returned a K a view).
- The pooled floor's closed-form quantiles (a track length's chi-square points, a pool's Student
  quantile) were computed unpaid: every track length up to 1,000 views about 1 s of CPU here, and
  pools of many degrees of freedom 2.3 ms each (the Student cache keeps 256). Fixed: charged to the
  verification's budget before they are computed (pooled_floor.charge_quantiles), once a document
  whether cached or not, so that a verdict does not depend on what the process verified before.

Found (a test below for each, which failed while the class stood):

1. A stratified autocalibration result stating what only the direct method writes verified: its
   relaxation's order, moment_rank (1: a moment relaxation solved exactly), eigenvalue_ratio and
   conic_status in a stage's summary (checks.SUMMARY_NOTES types them only; the direct method's
   are tied to its proof by _check_relaxation_figures), and Ks (a K a view, options.varying_focal)
   beside its one K, the direct document's or its own K repeated. Fixed:
   autocalibration._check_nothing_direct, on the stratified path.
2. The direct method's varying_focal hashed true beside a stratified proof verified with a scope
   saying nothing of it (read with its options: a K a view certified). The kind refuses such a
   job since review 50; an earlier writer served it, so the document verifies, and the scope now
   says the option is not read, as review 51 made it say of chirality.
3. A reconstruction summary's warnings ending in null, a bare "critical_motion" or a list
   verified: records.check left what is not a record to the checks reading the list, which pass
   over it. Fixed: an entry of a list of records must be a record.

Held (tried and refused, or accepted only where the edit claims nothing false):

- Every field of each stored result edited one at a time: refused but for informational figures
  (times, the registration's thresholds, focal rounds, initial pair, a projective stage's counts
  within their bounds and its RMS), numbers within their documented rounding (intervals and
  residuals nudged by 1e-6 of themselves, entries of a K within rounding of 0 or 1, a subnormal
  where 0 was), weaker statements (a determinacy or a note left out, a reason emptied), integers
  for their floats, warnings reordered.
- Each kind's members in every other kind's result, item, determinacy and summary: refused but
  for the two of class 1 (and proven_intervals null, which claims nothing).
- Options restated, hashes made again: rel_gap and metric_rel_gap 0 or subnormal (the kind allows
  0; abs_gap then certifies, and the scope says so), abs_gap 0, a convex bilinear job's
  coefficient_bound (which the convex coefficients do not read), run controls (unhashed,
  checked for range only: docs/certificate.md), chirality restated on a direct document (refused:
  its programs' rows), relaxation_order 3 (refused).
- Items reordered with their claims and data and the hashes made again (a true claim about the
  reordered job); result items, cameras, points or observations reordered alone: refused. A
  triangulation or resection certificate carried as a reconstruction's calibration or camera
  certificate, or a result given another kind: refused.
- A labelled reconstruction's camera renamed or two names swapped: refused (its input_labels).

Found, not fixed:

- summary.depth_reversal.mirror_capped is taken as stated (docs/certificate.md): whether a twin's
  adjustment stopped at its iteration cap is not derivable without running it again; stated false
  where it was true, a rejection read at the cap reads as one at the twin's minimum.
- A run control (max_nodes, time_limit_s) restated below what a proof's leaves or the stated
  times imply (max_nodes 1 beside a 30-leaf proof, a time limit of 5e-324 s) verifies: they are
  not hashed and are checked for range only, as documented.
"""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from geocert.core.strict import _WORK, Invalid, document_size, work_budget
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import refused_naming as _refused_naming, stored


# Review 51's first hole: summary.calibration.model restated "varying" beside one K

@pytest.mark.parametrize("name", ["reconstruction", "reconstruction_labelled"])
def test_a_calibration_model_restated_varying_beside_one_shared_K_is_refused(name):
    result = stored(name)
    assert result["summary"]["calibration"]["model"] == "shared"
    assert verify_any(result).valid
    forged = copy.deepcopy(result)
    forged["summary"]["calibration"]["model"] = "varying"
    _refused_naming(forged, "returned", "summary/calibration/model")


# Review 51's second hole: the pooled floor's closed-form quantiles not charged to the budget

@pytest.fixture(scope="module")
def pooled_pair() -> dict:
    """The triangulation example solved anew: two tracks pooled."""
    from geocert.jobs.runner import solve_job
    from geocert.kinds import get_kind

    example = get_kind("triangulation").example
    return json.loads(json.dumps(solve_job({**example, "options": {**example.get("options", {}),
                                                                   "certificate": "full"}})))


def test_a_budget_paying_for_all_but_the_pooled_quantiles_refuses_them(pooled_pair, monkeypatch):
    """The example's checks cost about 50 units of work beside its pooled level's quantiles (about
    2,400): a budget of 1,000 pays for the rest and not for them, refused naming them (unpaid,
    they verified)."""
    import geocert.verify.checks as checks

    assert verify_any(pooled_pair).valid
    monkeypatch.setattr(checks, "WORK_BASE", 1000 - checks.WORK_PER_UNIT * document_size(pooled_pair))
    _refused_naming(pooled_pair, "format", "more work than its size pays for", "quantiles")


def test_the_quantiles_of_every_track_length_are_charged_once_a_document_cached_or_not():
    """Every track length up to 1,000 views (their chi-square points from the closed form) and
    the pool's Student quantile: charged before they are computed, the same charge again with
    the process's caches warm, once for a document however many pools read them."""
    from geocert.verify.fractional import MAX_VIEWS
    from geocert.verify.pooled_floor import pooled_bounds

    dofs = 2.0 * np.arange(2, MAX_VIEWS + 1) - 3
    costs = dofs.copy()  # each track at its mean

    def charged(pools: int) -> int:
        left = 10 ** 9
        with work_budget(left):
            paid: set = set()
            for _ in range(pools):
                pooled_bounds(costs, dofs, paid)
            return left - _WORK.get()[0]

    first = charged(1)
    assert first > 10 ** 6  # about a second of CPU here, computed
    assert charged(1) == first and charged(3) == first  # the caches warm; three pools of one document
    with work_budget(first // 2), pytest.raises(Invalid, match="quantiles"):
        pooled_bounds(costs, dofs)


# Class 1: what only the direct method writes, stated beside a stratified result

STRATIFIED = ["autocalibration_stratified", "autocalibration_five_views"]


@pytest.mark.parametrize("name", STRATIFIED)
@pytest.mark.parametrize("figure", ["order", "moment_rank", "eigenvalue_ratio", "conic_status"])
@pytest.mark.parametrize("stage", [0, 1])
def test_a_direct_relaxations_figure_in_a_stratified_stages_summary_is_refused(name, figure, stage):
    """moment_rank 1 (a moment relaxation solved exactly, the optimum extracted) and its fellows,
    copied from the stored direct document's stage: the stratified stages solve no such relaxation,
    and the figures verified, typed only (checks.SUMMARY_NOTES)."""
    direct = stored("autocalibration_direct")["stages"][0]["certificate"]
    forged = stored(name)
    assert figure not in forged["stages"][stage]["certificate"]
    forged["stages"][stage]["certificate"][figure] = direct[figure]
    _refused_naming(forged, "returned", f"stages/{stage}/certificate/{figure}")


@pytest.mark.parametrize("name", STRATIFIED)
@pytest.mark.parametrize("which", ["direct's", "its own K"])
def test_a_K_a_view_beside_a_stratified_result_is_refused(name, which):
    """Ks (the direct method's K a view, options.varying_focal) says each camera was calibrated on
    its own; beside a stratified result's one K no check read it."""
    forged = stored(name)
    views = len(forged["cameras"])
    forged["Ks"] = (stored("autocalibration_direct")["Ks"][:views] if which == "direct's" else [forged["K"]] * views)
    _refused_naming(forged, "returned", "Ks")


# Class 2: the direct method's varying_focal hashed beside a stratified proof, the scope silent

@pytest.mark.parametrize("name", STRATIFIED)
def test_a_stratified_scope_says_varying_focal_is_not_read(name):
    """A stratified document hashing varying_focal true (a job the kind refuses since review 50,
    an earlier writer served) verified with a scope saying nothing of it: read with its options,
    a K a view certified, where the metric stage certifies one K for every view. The scope now
    says the option is not read, as it says of chirality (review 51)."""
    from tests.verify.test_forgeries import rehash

    forged = stored(name)
    forged["certificate"]["options"]["varying_focal"] = True
    rehash(forged["certificate"])
    report = verify_any(json.loads(json.dumps(forged)))
    assert report.valid, report.first_failure
    assert "not read by the stratified method" in report.scope["varying_focal"]
    assert "one K for every view" in report.scope["varying_focal"]


# Class 3: an entry of a list of records that is not one (a summary's warnings)

@pytest.mark.parametrize("name", ["reconstruction", "reconstruction_labelled"])
@pytest.mark.parametrize("entry", [None, "critical_motion", [], 0])
def test_a_warning_not_a_record_is_refused(name, entry):
    """A reconstruction summary's warnings ending in null, a bare code ("critical_motion", read
    as that warning and no check of its words reached) or a list verified: records.check left
    what is not a record to the checks reading the list, which pass over it."""
    forged = stored(name)
    forged["summary"]["warnings"].append(entry)
    _refused_naming(forged, "returned", f"summary/warnings/{len(forged['summary']['warnings']) - 1}")
