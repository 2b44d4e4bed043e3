// "/jobs/{id}": live progress from the job's event stream; once it ends, the items, the residuals,
// a 3D view, links and verification. Items are paged here, in the browser, from the result the
// page already holds (see README: one parse of the result, instant filters and sorts).
"use strict";

(() => {
  const {el, num, duration} = GC;
  const jobId = decodeURIComponent(location.pathname.split("/").filter(Boolean).pop() || "");
  const state = {job: null, kinds: null, chart: null, stream: null, table: null, view: null, request: undefined,
                 finishedShown: false};
  window.GC_STATE = {jobId, rendered: null, chart: null, view: null, verify: null, timings: {}};
  const mark = (name) => { if (!(name in window.GC_STATE.timings)) window.GC_STATE.timings[name] = Math.round(performance.now()); };

  const $ = (id) => document.getElementById(id);

  function showProgress(p, status) {
    if (!p) return;
    $("s-items").textContent = `${p.items_done ?? 0} / ${p.items_total ?? 0}`;
    $("s-nodes").textContent = num(p.nodes);
    $("s-open").textContent = num(p.open_boxes);
    $("s-upper").textContent = num(p.upper_bound);
    $("s-lower").textContent = num(p.lower_bound);
    $("s-gap").textContent = `${num(p.gap_abs)} / ${p.gap_rel === null || p.gap_rel === undefined ? "—" : num(p.gap_rel)}`;
    $("s-elapsed").textContent = duration(p.elapsed_s);
    $("s-stage").textContent = p.stage || "—";
    if (p.elapsed_s !== undefined && (p.upper_bound !== null || p.lower_bound !== null))
      state.chart.add(p.elapsed_s, p.upper_bound, p.lower_bound, p.gap_abs);
  }

  function showStatus(status) {
    const badge = $("status");
    badge.textContent = status;
    badge.className = `status ${status}`;
    $("cancel").disabled = GC.TERMINAL.has(status);
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
      showProgress(job.progress);
      await showFinished(job);
    }
    return job;
  }

  function onEvent(name, data) {
    if (name === "progress") showProgress(data);
    else if (name === "status") showStatus(data.status);
    else if (name === "end") {
      showStatus(data.status);
      if (!state.finishedShown) refresh().catch(GC.showError);  // (a finished job's replayed stream: shown already)
    } else if (name === "error") GC.showError(data.message);
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
    if (!kindsPromise) kindsPromise = GC.json("/v1/problems").catch(() => []);
    return kindsPromise;
  }

  async function itemKey(kind, result) {
    if (!state.kinds) state.kinds = await kinds();
    const info = state.kinds.find((k) => k.kind === kind);
    if (info && Array.isArray(result[info.item_name])) return info.item_name;
    for (const key of ["tracks", "maps", "stages", "items"]) if (Array.isArray(result[key])) return key;
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
    for (const [name, path] of Object.entries(job.links || {}))
      if (!["self", "events", "cancel"].includes(name) && typeof path === "string") items.push(link(`Export: ${name}`, path, `${jobId}-${name}`));
    const exports = job.result && job.result.exports;
    if (exports && typeof exports === "object")
      for (const [name, path] of Object.entries(exports)) if (typeof path === "string") items.push(link(`Export: ${name}`, path, `${jobId}-${name}`));
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

  // --- items table -----------------------------------------------------------------------------
  const COLUMNS = [
    {key: "index", label: "#", num: true},
    {key: "name", label: "name", optional: true},
    {key: "status", label: "status"},
    {key: "certified", label: "certified"},
    {key: "cost", label: "cost", num: true},
    {key: "lower_bound", label: "lower bound", num: true},
    {key: "gap", label: "gap", num: true},
    {key: "nodes", label: "nodes", num: true},
    {key: "elapsed_s", label: "time (s)", num: true},
  ];

  class ItemTable {
    constructor(items) {
      this.n = items.length;
      this.columns = COLUMNS.filter((c) => !c.optional || items.some((it) => it && it[c.key] !== undefined));
      this.data = {};
      for (const c of this.columns) {
        const values = new Array(this.n);
        for (let i = 0; i < this.n; i++) values[i] = c.key === "index" ? i : (items[i] ? items[i][c.key] : null);
        this.data[c.key] = values;
      }
      this.reasons = items.map((it) => (it && it.reason) || "");
      this.sortKey = "index"; this.sortDir = 1; this.page = 0; this.size = 50;
      this.order = null;
      const statuses = [...new Set(this.data.status)].filter((s) => s !== undefined && s !== null).sort();
      $("f-status").replaceChildren(el("option", {value: "", text: "any"}), ...statuses.map((s) => el("option", {value: s, text: s})));
      for (const id of ["f-status", "f-certified", "f-size"]) $(id).addEventListener("change", () => this.update(true));
      $("f-gap").addEventListener("input", () => this.update(true));
      $("first").addEventListener("click", () => { this.page = 0; this.render(); });
      $("prev").addEventListener("click", () => { this.page = Math.max(0, this.page - 1); this.render(); });
      $("next").addEventListener("click", () => { this.page = Math.min(this.pages() - 1, this.page + 1); this.render(); });
      $("last").addEventListener("click", () => { this.page = this.pages() - 1; this.render(); });
      this.head();
      this.update(true);
    }

    head() {
      const cells = this.columns.map((c) => {
        const sorted = this.sortKey === c.key;
        return el("th", {class: c.num ? "num" : null, "aria-sort": sorted ? (this.sortDir > 0 ? "ascending" : "descending") : null},
          el("button", {type: "button", "data-sort": c.key, onclick: () => this.sortBy(c.key),
                        text: `${c.label}${sorted ? (this.sortDir > 0 ? " ▲" : " ▼") : ""}`}));
      });
      document.querySelector("#items thead").replaceChildren(el("tr", {}, cells));
    }

    sortBy(key) {
      if (this.sortKey === key) this.sortDir = -this.sortDir; else { this.sortKey = key; this.sortDir = 1; }
      this.head();
      this.update(false);
      const button = document.querySelector(`#items thead button[data-sort="${key}"]`);
      if (button) button.focus();
    }

    update(resetPage) {
      const status = $("f-status").value, certified = $("f-certified").value;
      const gapMin = parseFloat($("f-gap").value);
      this.size = parseInt($("f-size").value, 10) || 50;
      const d = this.data, order = [];
      for (let i = 0; i < this.n; i++) {
        if (status && d.status[i] !== status) continue;
        if (certified && (certified === "yes") !== Boolean(d.certified[i])) continue;
        if (Number.isFinite(gapMin) && !(d.gap[i] >= gapMin)) continue;
        order.push(i);
      }
      const values = d[this.sortKey], dir = this.sortDir;
      if (this.sortKey !== "index" || dir < 0) {
        order.sort((a, b) => {
          const x = values[a], y = values[b];
          const xn = x === null || x === undefined, yn = y === null || y === undefined;
          if (xn || yn) return xn === yn ? a - b : (xn ? 1 : -1);  // missing values last
          if (x < y) return -dir;
          if (x > y) return dir;
          return a - b;
        });
      }
      this.order = order;
      if (resetPage) this.page = 0;
      this.render();
    }

    pages() { return Math.max(1, Math.ceil(this.order.length / this.size)); }

    render() {
      const d = this.data, start = this.page * this.size, rows = [];
      for (const i of this.order.slice(start, start + this.size)) {
        rows.push(el("tr", {"data-item": i}, this.columns.map((c) => {
          const v = d[c.key][i];
          if (c.key === "status") return el("td", {title: this.reasons[i] || null}, el("span", {class: `status ${v}`, text: v ?? "—"}));
          if (c.key === "certified") return el("td", {text: v ? "yes" : "no"});
          if (c.key === "index") return el("td", {class: "num", text: v});
          return el("td", {class: c.num ? "num" : null, text: c.num ? num(v) : (v ?? "—")});
        })));
      }
      if (!rows.length) rows.push(el("tr", {}, el("td", {colspan: this.columns.length, class: "note", text: "No items match."})));
      document.querySelector("#items tbody").replaceChildren(...rows);
      const pages = this.pages();
      $("page-note").textContent = `${this.order.length} of ${this.n} items; page ${this.page + 1} of ${pages}`;
      $("first").disabled = $("prev").disabled = this.page === 0;
      $("next").disabled = $("last").disabled = this.page >= pages - 1;
    }
  }

  // --- geometry: residuals and the 3D view ----------------------------------------------------------
  function det3(m) {
    return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
           m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
  }

  const norm3 = (v) => { const n = Math.hypot(v[0], v[1], v[2]) || 1; return [v[0] / n, v[1] / n, v[2] / n]; };
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];

  // A 3x4 projective camera: its centre (the null vector, by minors) and axes (right, down, forward).
  function cameraOf(P) {
    if (!Array.isArray(P) || P.length !== 3 || P.some((row) => !Array.isArray(row) || row.length !== 4)) return null;
    const minor = (skip) => det3(P.map((row) => row.filter((_, j) => j !== skip)));
    const c = [minor(0), -minor(1), minor(2), -minor(3)];
    if (!c[3]) return null;
    const center = [c[0] / c[3], c[1] / c[3], c[2] / c[3]];
    const M = P.map((row) => row.slice(0, 3));
    const sign = det3(M) >= 0 ? 1 : -1;
    const forward = norm3(M[2].map((v) => sign * v));
    const right = norm3(cross(forward, cross(M[0], forward)));  // m1 with its forward part removed
    const down = cross(forward, right);
    return {center, axes: [right, down, forward]};
  }

  function toPoint(p) {
    if (p && !Array.isArray(p)) p = p.point || p.xyz || p.X || null;
    if (!Array.isArray(p) || p.length < 3 || !p.every(Number.isFinite)) return null;
    if (p.length === 4) return p[3] ? [p[0] / p[3], p[1] / p[3], p[2] / p[3]] : null;
    return p.slice(0, 3);
  }

  function scene(result, items, req) {
    let points = [];
    if (Array.isArray(result.points)) points = result.points.map(toPoint).filter(Boolean);
    else if (items.some((it) => it && Array.isArray(it.point)))
      points = items.filter((it) => it && !it.at_infinity).map((it) => toPoint(it.point)).filter(Boolean);
    let cameras = [];
    if (Array.isArray(result.cameras) && result.cameras.some((c) => c && Array.isArray(c.center))) {
      cameras = result.cameras.filter((c) => c && Array.isArray(c.center)).map((c) => ({
        center: c.center,
        axes: Array.isArray(c.R) && c.R.length === 3 ? [norm3(c.R[0]), norm3(c.R[1]), norm3(c.R[2])] : null}));
    } else if (req && req.data && Array.isArray(req.data.cameras)) {
      cameras = req.data.cameras.map(cameraOf).filter(Boolean);
    }
    return {points, cameras};
  }

  // Per observation residual lengths: the items' own (maps), or reprojected from the request (tracks).
  function residuals(items, req, itemKeyName) {
    const values = [];
    if (items.some((it) => it && Array.isArray(it.residuals))) {
      for (const it of items) for (const r of (it && it.residuals) || []) values.push(Array.isArray(r) ? Math.hypot(...r) : Math.abs(r));
      return {values, unit: "residual length, target units"};
    }
    const cams = req && req.data && req.data.cameras, inputs = req && req.data && req.data[itemKeyName];
    if (Array.isArray(cams) && Array.isArray(inputs) && items.some((it) => it && Array.isArray(it.point))) {
      items.forEach((it, i) => {
        const input = inputs[i];
        if (!it || !Array.isArray(it.point) || !input || !Array.isArray(input.views)) return;
        const X = it.point.length === 4 ? it.point : [...it.point, 1];
        for (let j = 0; j < input.views.length; j++) {
          const P = cams[input.views[j]], obs = input.points[j];
          if (!P || !obs) continue;
          const [a, b, c] = P;
          const w = c[0] * X[0] + c[1] * X[1] + c[2] * X[2] + c[3] * X[3];
          if (!w) continue;
          const u = (a[0] * X[0] + a[1] * X[1] + a[2] * X[2] + a[3] * X[3]) / w - obs[0];
          const v = (b[0] * X[0] + b[1] * X[1] + b[2] * X[2] + b[3] * X[3]) / w - obs[1];
          values.push(Math.sqrt(u * u + v * v));
        }
      });
      return {values, unit: "reprojection error, pixels"};
    }
    return null;
  }

  async function showFinished(job) {
    if (state.finishedShown) return;
    state.finishedShown = true;
    $("finished").hidden = false;
    if (job.error) GC.showError(`${job.error.title}: ${job.error.detail || ""}`);
    const result = job.result;
    showLinks(job);
    const hasFull = Boolean(result && result.certificate);
    $("verify").disabled = !hasFull;
    $("verify-note").textContent = hasFull ? "" : "No full certificate: submit with options.certificate = \"full\" to verify.";
    if (!result) { window.GC_STATE.rendered = performance.now(); return; }
    const key = await itemKey(job.kind, result);
    const items = key ? result[key] : [];
    const stats = result.stats || {};
    $("summary").textContent = `${stats.items ?? items.length} ${key || "items"}, ${stats.certified ?? "—"} certified, ` +
      `${num(stats.nodes)} nodes, ${duration(stats.elapsed_s)}.`;
    state.table = new ItemTable(items);
    mark("table");
    const needsRequest = items.some((it) => it && Array.isArray(it.point)) &&
                         !items.some((it) => it && Array.isArray(it.residuals));
    const req = needsRequest ? await request() : null;
    mark("request");
    const res = residuals(items, req, key);  // {values, unit} or null
    if (res && res.values.length) {
      const h = Charts.histogram($("histogram"), res.values, res.unit);
      $("hist-note").textContent = `${h.count} residuals (${res.unit}); median ${num(h.median)}, largest ${num(h.max)}` +
        (h.over ? `; ${h.over} above ${num(h.cut)} (the 99th percentile) not drawn.` : ".");
    } else {
      const costs = items.map((it) => it && it.cost).filter(Number.isFinite);
      if (costs.length >= 3) {
        Charts.histogram($("histogram"), costs, "item cost");
        $("hist-note").textContent = "This result carries no per-observation residuals: the items' costs are shown.";
      } else {
        $("histogram").hidden = true;
        $("hist-note").textContent = "This result carries no per-observation residuals (its items' costs are in the table).";
      }
    }
    mark("histogram");
    const {points, cameras} = scene(result, items, req);
    if (points.length || cameras.length) {
      $("view-section").hidden = false;
      state.view = new Charts.View3D($("view3d"), points, cameras);
      $("view-reset").addEventListener("click", () => state.view.reset());
      window.GC_STATE.view = {points: points.length, cameras: cameras.length};
      $("view-note").textContent = "Drag, or focus the view and use the arrow keys, to rotate; the wheel or + and − zoom.";
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
      state.stream = GC.stream(`/v1/jobs/${encodeURIComponent(jobId)}/events`, onEvent);
      state.chart.draw();
      return job;
    }).catch(GC.showError);
  });
})();
