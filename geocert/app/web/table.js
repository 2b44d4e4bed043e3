// The items of a result in a table paged, filtered and sorted in the browser (docs/api.md, the web page: one parse
// of the result, instant filters and sorts). Each row shows the answer itself (a point, a
// matrix, a motion) and how well the data fix it, beside the bounds.
"use strict";

const ItemTable = (() => {
  const {el, num} = GC;
  const $ = (id) => document.getElementById(id);

  const COLUMNS = () => [
    {key: "index", label: "#", num: true},
    {key: "name", label: "name", optional: true},
    {key: "status", label: "status"},
    {key: "certified", label: "certified"},
    {key: "answer", label: "answer", derived: true, sortable: false},
    {key: "determinacy", label: "determined", derived: true},
    {key: "cost", label: "cost", num: true, optional: true},
    {key: "lower_bound", label: "lower bound", num: true, optional: true},
    {key: "gap", label: "gap", num: true, optional: true},
    {key: "inlier_ratio", label: "inlier ratio", num: true, optional: true},
    {key: "rms_px", label: "RMS (px)", num: true, optional: true},
    {key: "nodes", label: "nodes", num: true, optional: true, hideZero: true},
    {key: "elapsed_s", label: "time (s)", num: true},
    {key: "reason", label: "reason", optional: true},
  ];

  class Table {
    constructor(items) {
      this.items = items;
      this.n = items.length;
      this.answers = new Array(this.n);  // made when a row is first drawn: 10^5 items cost nothing up front
      const determinacy = items.map((it) => Answer.determinacy(it));
      const present = (c) => {
        if (c.key === "answer") return items.some(Answer.hasSolution);
        if (c.key === "determinacy") return determinacy.some(Boolean);
        // an optional column only when some item has a value there (a kind of estimates has no bounds)
        return !c.optional || items.some((it) => it && it[c.key] !== undefined && it[c.key] !== null && !(c.hideZero && it[c.key] === 0));
      };
      this.columns = COLUMNS().filter(present);
      const answer = this.columns.find((c) => c.key === "answer");
      if (answer) answer.label = Answer.solutionLabel(items);
      this.data = {};
      for (const c of this.columns) {
        const values = new Array(this.n);
        for (let i = 0; i < this.n; i++) {
          if (c.key === "index") values[i] = i;
          else if (c.key === "determinacy") values[i] = determinacy[i] ? determinacy[i].text : null;
          else if (!c.derived) values[i] = items[i] ? items[i][c.key] : null;
        }
        this.data[c.key] = values;
      }
      this.flagged = determinacy.map((d) => Boolean(d && d.bad));
      for (const key of ["status", "certified", "gap"]) if (!this.data[key]) this.data[key] = items.map((it) => it && it[key]);
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
        if (c.sortable === false) return el("th", {text: c.label});
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

    cell(c, i) {
      const v = this.data[c.key] ? this.data[c.key][i] : null;
      const reason = this.items[i] && this.items[i].reason;
      if (c.key === "status") return el("td", {title: reason || null}, el("span", {class: `status ${v}`, text: v ?? "—"}));
      if (c.key === "certified") return el("td", {}, el("span", {class: `status ${v ? "yes" : "no"}`, text: v ? "yes" : "no"}));
      if (c.key === "index") return el("td", {class: "num", text: v});
      if (c.key === "answer") {
        if (this.answers[i] === undefined) this.answers[i] = Answer.solution(this.items[i]);
        return el("td", {class: "answer"}, this.answers[i] ? this.answers[i].cloneNode(true) : "—");
      }
      if (c.key === "determinacy") return el("td", {class: this.flagged[i] ? "flag" : null, text: v ?? "—"});
      if (c.key === "reason") return el("td", {class: "reason", title: v || null, text: v ?? ""});
      return el("td", {class: c.num ? "num" : null, text: c.num ? num(v) : (v ?? "—")});
    }

    render() {
      const start = this.page * this.size, rows = [];
      for (const i of this.order.slice(start, start + this.size)) {
        rows.push(el("tr", {"data-item": i, class: this.data.certified[i] ? null : "uncertified"}, this.columns.map((c) => this.cell(c, i))));
      }
      if (!rows.length) rows.push(el("tr", {}, el("td", {colspan: this.columns.length, class: "note", text: "No items match."})));
      document.querySelector("#items tbody").replaceChildren(...rows);
      const pages = this.pages();
      $("page-note").textContent = `${this.order.length} of ${this.n} items; page ${this.page + 1} of ${pages}`;
      $("first").disabled = $("prev").disabled = this.page === 0;
      $("next").disabled = $("last").disabled = this.page >= pages - 1;
    }
  }

  return Table;
})();
