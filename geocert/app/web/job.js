// "/jobs/{id}": live progress from the job's event stream; once it ends, first what the result
// proves and what it does not (truth.js), then the answer (answer.js), the items (table.js), the
// residuals and a 3D view (geometry.js), links, exports and verification.
"use strict";

(() => {
  const {el, num, duration} = GC;
  const jobId = decodeURIComponent(location.pathname.split("/").filter(Boolean).pop() || "");
  const state = {job: null, kinds: null, chart: null, stream: null, table: null, view: null, shown: null,
                 finishedShown: false};
  window.GC_STATE = {jobId, rendered: null, chart: null, view: null, verify: null, verdict: null, statuses: [],
                     timings: {}};
  const mark = (name) => { if (!(name in window.GC_STATE.timings)) window.GC_STATE.timings[name] = Math.round(performance.now()); };

  const $ = (id) => document.getElementById(id);

  function showProgress(p, chart = true) {
    if (!p) return;
    $("s-items").textContent = `${p.items_done ?? 0} / ${p.items_total ?? 0}`;
    $("s-nodes").textContent = num(p.nodes);
    $("s-open").textContent = num(p.open_boxes);
    $("s-upper").textContent = num(p.upper_bound);
    $("s-lower").textContent = num(p.lower_bound);
    $("s-gap").textContent = `${num(p.gap_abs)} / ${p.gap_rel === null || p.gap_rel === undefined ? "—" : num(p.gap_rel)}`;
    $("s-elapsed").textContent = duration(p.elapsed_s);
    $("s-stage").textContent = p.stage || "—";
    if (chart) chartProgress(p);
  }

  function chartProgress(p) {
    if (p && p.elapsed_s !== undefined) state.chart.add(p.elapsed_s, p.upper_bound, p.lower_bound, p.gap_abs, p.stage);
  }

  // A status only moves forward (queued, running, then an end): a stream replayed from its start
  // after the job was read must not take the badge back to "running".
  const RANK = {queued: 0, running: 1, succeeded: 2, failed: 2, cancelled: 2};
  function showStatus(status) {
    if (state.shown && (RANK[status] ?? 0) < (RANK[state.shown] ?? 0)) return;
    if (state.shown && GC.TERMINAL.has(state.shown)) return;
    state.shown = status;
    window.GC_STATE.statuses.push(status);
    const badge = $("status");
    badge.textContent = status;
    badge.className = `status ${status}`;
    const ended = GC.TERMINAL.has(status);
    $("cancel").disabled = ended;
    $("cancel").hidden = ended;
    document.title = `geocert — ${status} — ${jobId.slice(0, 8)}`;
  }

  async function refresh() {
    const response = await GC.api(`/v1/jobs/${encodeURIComponent(jobId)}`);
    mark("answered");
    const text = await response.text();
    mark("received");
    if (!response.ok) throw new GC.ApiError(response.status, JSON.parse(text || "null"));
    const job = JSON.parse(text);
    mark("job");
    state.job = job;
    // Verification posts the document as the server sent it: JavaScript would write 1.0 back as 1,
    // and a certificate's data hash is over the exact JSON numbers (canonical_json).
    state.jobText = text;
    $("s-kind").textContent = job.kind;
    showStatus(job.status);
    if (GC.TERMINAL.has(job.status)) {
      showProgress(job.progress, state.stream !== null);  // opened on an ended job: its history is replayed instead
      await showFinished(job);
    }
    return job;
  }

  function onEvent(name, data) {
    if (name === "progress") showProgress(data);
    else if (name === "status") showStatus(data.status);
    else if (name === "end") {
      showStatus(data.status);
      if (!state.finishedShown) refresh().catch(GC.showError);
      else chartDone();
    } else if (name === "error") GC.showError(data.message);
  }

  // A job that had ended when the page opened: its stream is read from the start for the chart
  // only (the history of its bounds); the status shown is the job's.
  function onReplayed(name, data) {
    if (name === "progress") chartProgress(data);
    else if (name === "end") chartDone();
  }

  function chartDone() {
    if (!state.chart.points.length && state.job) chartProgress(state.job.progress);  // no history kept: the end at least
    const certifies = kindInfo() ? kindInfo().certifies !== false : true;
    const none = certifies ? "No bounds were reported before the job ended." : "No bounds: this kind returns estimates, not certified bounds.";
    state.chart.finish(none);
    const drawn = state.chart.drawable().length > 0;
    $("chart").hidden = !drawn;  // an empty canvas says nothing the note does not
    $("chart-legend").hidden = !drawn;
    $("chart-note").textContent = drawn ? state.chart.summary() : none;
  }

  async function cancel() {
    $("cancel").disabled = true;
    try {
      const job = await GC.json(`/v1/jobs/${encodeURIComponent(jobId)}/cancel`, {method: "POST"});
      showStatus(job.status);
      if (GC.TERMINAL.has(job.status)) await refresh();
    } catch (error) {
      GC.showError(error);
      $("cancel").disabled = false;
    }
  }

  // Asked for at once, beside the job itself: a finished job's page needs both.
  let kindsPromise = null;
  function kinds() {
    if (!kindsPromise) kindsPromise = GC.json("/v1/problems").catch(() => []).then((list) => { state.kinds = list; return list; });
    return kindsPromise;
  }
  const kindInfo = () => (state.kinds || []).find((k) => state.job && k.kind === state.job.kind);

  function itemKey(result) {
    const info = kindInfo();
    if (info && Array.isArray(result[info.item_name])) return info.item_name;
    for (const key of ["tracks", "maps", "stages", "frames", "pairs", "points", "items"]) if (Array.isArray(result[key])) return key;
    return null;
  }

  let requestPromise = null;
  function request() {
    if (!requestPromise) requestPromise = GC.json(`/v1/jobs/${encodeURIComponent(jobId)}/request`).catch(() => null);
    return requestPromise;
  }

  // --- links -----------------------------------------------------------------------------------
  function link(label, path, filename) {
    return el("li", {}, el("a", {href: path, onclick: (event) => {
      if (!sessionStorage.getItem(GC.keyName)) return;  // no key: the plain link works
      event.preventDefault();
      GC.download(path, filename).catch(GC.showError);
    }, text: label}));
  }

  function showLinks(job) {
    const base = `/v1/jobs/${encodeURIComponent(jobId)}`;
    const items = [link("Result JSON", base, `${jobId}.json`), link("Request JSON", `${base}/request`, `${jobId}-request.json`)];
    if (job.result && job.result.certificate) items.push(link("Certificate", `${base}/certificate`, `${jobId}-certificate.json`));
    for (const [label, path, filename] of Answer.exports(job)) items.push(link(`Export: ${label}`, path, filename));
    $("links").replaceChildren(...items);
  }

  // --- verification ----------------------------------------------------------------------------
  async function verify() {
    const button = $("verify");
    button.disabled = true;
    $("verify-note").textContent = "Verifying…";
    try {
      const report = await GC.json("/v1/certificates/verify", {method: "POST", body: state.jobText,
                                                                headers: {"Content-Type": "application/json"}});
      window.GC_STATE.verify = report;
      const rows = report.checks.map((c) => el("tr", {"data-check": c.name},
        el("td", {text: c.name}), el("td", {class: "num", text: c.passed}), el("td", {class: "num", text: c.failed}),
        el("td", {}, el("span", {class: `status ${c.failed ? "no" : "yes"}`, text: c.failed ? "failed" : "passed"}))));
      const parts = [
        el("p", {}, el("span", {id: "verify-verdict", class: `status ${report.valid ? "yes" : "no"}`,
                                text: report.valid ? "valid" : "not valid"}),
           ` ${report.items_checked} items checked, ${report.items_skipped} skipped (not claimed certified).`),
        el("div", {class: "table-wrap"}, el("table", {class: "checks"},
          el("thead", {}, el("tr", {}, el("th", {text: "check"}), el("th", {class: "num", text: "passed"}),
                                  el("th", {class: "num", text: "failed"}), el("th", {text: ""}))),
          el("tbody", {}, rows)))];
      if (report.first_failure) {
        const f = report.first_failure;
        parts.push(el("p", {class: "error", text: `First failure: ${f.check}${f.item !== null ? ` (item ${f.item})` : ""}: ${f.detail}`}));
      }
      if (report.scope) parts.push(el("details", {}, el("summary", {text: "Scope: what a valid certificate proves"}),
                                       el("pre", {class: "scope", text: JSON.stringify(report.scope, null, 2)})));
      $("verify-report").replaceChildren(...parts);
      $("verify-note").textContent = "";
    } catch (error) {
      $("verify-note").textContent = "";
      GC.showError(error);
    } finally {
      button.disabled = false;
    }
  }

  // --- what the result proves, first --------------------------------------------------------------
  function showVerdict(job, result, key) {
    const info = kindInfo();
    const v = Truth.verdict(job, result, key, info ? info.certifies : undefined);
    window.GC_STATE.verdict = {level: v.level, headline: v.headline, lines: v.lines.map((l) => l.text)};
    $("verdict").className = `verdict ${v.level}`;
    $("verdict-headline").textContent = v.headline;
    $("verdict-lines").replaceChildren(...v.lines.map((line) => el("li", {class: line.level, "data-kind": line.kind, text: line.text})));
  }

  // Exceptions a failure names, in words.
  const CAUSES = {
    SoftTimeLimitExceeded: "the service's time limit for one task stopped it (not the job's own time_limit_s)",
    TimeLimitExceeded: "the service's time limit for one task stopped it (not the job's own time_limit_s)",
    MemoryError: "it ran out of memory",
  };

  // A failed job: what failed, in words, what it finished, then the error as reported.
  function showFailure(job) {
    const error = job.error || {};
    const p = job.progress || {};
    const fields = (error.errors || []).map((e) => el("li", {}, el("code", {text: e.field}), `: ${e.reason}`));
    const cause = Object.entries(CAUSES).find(([name]) => String(error.detail || "").startsWith(`${name}:`));
    const plain = error.status === 422
      ? "Its data were refused when it ran (the submission was accepted, so this is a check the service should have made at once)."
      : error.status >= 500 ? `The solver stopped with an internal error${cause ? `: ${cause[1]}` : ""}. ` +
                              "This is a fault of the service, not of your data." : "";
    const parts = [
      el("p", {id: "failure-title", class: "flag", text: `${error.title || "Failed"}${error.status ? ` (${error.status})` : ""}`}),
      plain ? el("p", {text: plain}) : null,
      el("p", {id: "failure-detail", text: error.detail ? `The error reported: ${error.detail}` : "No detail was recorded."}),
      fields.length ? el("ul", {class: "plain"}, fields) : null,
      el("p", {class: "note", text: `Finished before it failed: ${p.items_done ?? 0} of ${p.items_total ?? 0} items` +
                                    `${p.stage ? ` (it was at stage ${p.stage}, after ${duration(p.elapsed_s)})` : ""}` +
                                    `${job.result ? "; what finished is in the result below" : "; no result was kept"}.`}),
    ];
    $("failure").replaceChildren(...parts.filter(Boolean));
    $("failure").hidden = false;
  }

  function showHistogram(result, items, key, req) {
    const res = Geometry.residuals(result, items, req, key);  // {values, unit} or null
    if (res && res.values.length) {
      const h = Charts.histogram($("histogram"), res.values, res.unit);
      $("hist-note").textContent = `${h.count} residuals (${res.unit}); median ${num(h.median)}, largest ${num(h.max)}` +
        (h.over ? `; ${h.over} above ${num(h.cut)} (the 99th percentile) not drawn.` : ".");
      return;
    }
    const costs = items.map((it) => it && it.cost).filter(Number.isFinite);
    if (costs.length >= 3) {
      Charts.histogram($("histogram"), costs, "item cost");
      $("hist-note").textContent = "This result carries no per-observation residuals: the items' costs are shown.";
    } else {
      $("hist-section").hidden = true;  // nothing to draw: the panel would be empty
      $("panels").classList.add("single");
    }
  }

  async function showFinished(job) {
    if (state.finishedShown) return;
    state.finishedShown = true;
    await kinds();
    $("finished").hidden = false;
    const result = job.result;
    if (job.status === "failed") showFailure(job);
    showLinks(job);
    const info = kindInfo();
    const certifies = !info || info.certifies !== false;
    const hasFull = Boolean(result && result.certificate);
    $("verify-row").hidden = !certifies || !result;
    $("verify").disabled = !hasFull;
    $("verify-note").textContent = hasFull ? "" : "No full certificate: submit with options.certificate = \"full\" to verify.";
    const key = result ? itemKey(result) : null;
    showVerdict(job, result, key);
    $("verdict").hidden = false;
    if (!result) {
      $("result-parts").hidden = true;
      window.GC_STATE.rendered = performance.now();
      return;
    }
    const items = key ? result[key] : [];
    const certified = items.filter((it) => it && it.certified).length;
    const name = key || "items";
    $("summary").textContent = `${items.length} ${items.length === 1 ? name.replace(/s$/, "") : name}` +
      `${certifies ? `, ${certified} certified` : " (estimates)"}, ` +
      `${num(result.stats && result.stats.nodes)} nodes, ${duration(result.stats && result.stats.elapsed_s)}.`;
    $("answer").replaceChildren(...Answer.figures(job.kind, result));
    $("items-title").textContent = key ? key[0].toUpperCase() + key.slice(1) : "Items";
    state.table = new ItemTable(items);
    mark("table");
    const needsRequest = items.some((it) => it && Array.isArray(it.point)) &&
                         !items.some((it) => it && (Array.isArray(it.residuals) || Array.isArray(it.observations)));
    const req = needsRequest ? await request() : null;
    mark("request");
    showHistogram(result, items, key, req);
    mark("histogram");
    const {points, cameras} = Geometry.scene(result, items, req);
    if (points.length || cameras.length) {
      $("view-section").hidden = false;
      state.view = new Charts.View3D($("view3d"), points, cameras);
      $("view-reset").addEventListener("click", () => state.view.reset());
      window.GC_STATE.view = {points: points.length, cameras: cameras.length};
      $("view-note").textContent = "Drag, or focus the view and use the arrow keys, to rotate; the wheel or + and − zoom.";
    } else {
      $("panels").classList.add("single");  // the histogram alone: the whole width
    }
    window.GC_STATE.rendered = performance.now();
  }

  document.addEventListener("DOMContentLoaded", () => {
    mark("ready");
    $("job-id").textContent = jobId;
    state.chart = new Charts.BoundChart($("chart"));
    window.GC_STATE.chart = state.chart.points;
    $("cancel").addEventListener("click", cancel);
    $("verify").addEventListener("click", verify);
    // Beside the job itself: a finished job's page needs the kinds (the name of its items) and, to
    // reproject tracks, the request; fetched at once, they cost no time after the job arrives.
    kinds();
    request();
    refresh().then((job) => {
      const ended = GC.TERMINAL.has(job.status);
      state.stream = GC.stream(`/v1/jobs/${encodeURIComponent(jobId)}/events`, ended ? onReplayed : onEvent);
      state.chart.draw();
      return job;
    }).catch(GC.showError);
  });
})();
