// The answer itself, as a person reads it: an item's solution (a point, a matrix, a motion), a
// kind's key figures (a reconstruction's summary and stages, an autocalibration's K against its
// ranges and how well the data fix it), and a result's other lists of claims (a reconstruction's
// cameras). Each figure says where it comes from and whether it is certified.
"use strict";

const Answer = (() => {
  const {el, num} = GC;
  const isMatrix = (m) => Array.isArray(m) && m.length > 0 && m.every((row) => Array.isArray(row) && row.every((v) => v === null || typeof v === "number"));
  const isVector = (v) => Array.isArray(v) && v.length > 0 && v.every((x) => x === null || typeof x === "number");
  const fmt = (v) => (v === null || v === undefined ? "—" : num(v, 4));

  function matrix(m) {
    const cells = m.map((row) => row.map(fmt));
    const width = Math.max(...cells.flat().map((c) => c.length));
    return el("pre", {class: "matrix", text: cells.map((row) => row.map((c) => c.padStart(width)).join("  ")).join("\n")});
  }

  function vector(v) { return el("span", {class: "vector", text: `[${v.map(fmt).join(", ")}]`}); }

  function value(v) {
    if (isMatrix(v)) return matrix(v);
    if (isVector(v)) return vector(v);
    if (typeof v === "boolean") return v ? "yes" : "no";
    if (typeof v === "number") return num(v);
    if (v === null || v === undefined) return "—";
    return typeof v === "object" ? JSON.stringify(v) : String(v);
  }

  // Rotation angle (degrees) of a 3x3 rotation matrix.
  function angle(R) {
    const c = (R[0][0] + R[1][1] + R[2][2] - 1) / 2;
    return Math.acos(Math.max(-1, Math.min(1, c))) * 180 / Math.PI;
  }

  // An item's solution, whatever the kind: the fields it carries, in this order.
  const SOLUTION = ["point", "matrix", "K", "Ks", "plane_at_infinity", "R", "t", "camera", "coefficients"];

  const hasSolution = (item) => Boolean(item && typeof item === "object" && SOLUTION.some((k) => item[k] !== undefined && item[k] !== null));

  function solution(item) {
    if (!item || typeof item !== "object") return null;
    const parts = [];
    for (const key of SOLUTION) {
      const v = item[key];
      if (v === undefined || v === null) continue;
      if (key === "R" && isMatrix(v) && v.length === 3) { parts.push(el("div", {text: `R: ${fmt(angle(v))}°`})); continue; }
      if (key === "point" && item.at_infinity) { parts.push(el("div", {}, "at infinity ", vector(v))); continue; }
      const shown = value(v);
      parts.push(isMatrix(v) ? el("div", {}, el("span", {class: "label", text: key === "matrix" ? "" : `${key}`}), shown)
                             : el("div", {}, key === "point" ? "" : `${key}: `, shown));
    }
    return parts.length ? el("div", {class: "solution"}, parts) : null;
  }

  // What the answer column holds: the solution fields the items carry ("point", "matrix", ...).
  function solutionLabel(items) {
    const keys = new Set();
    for (const it of items.slice(0, 50)) for (const key of SOLUTION) if (it && it[key] !== undefined && it[key] !== null) keys.add(key);
    return keys.size ? [...keys].map((k) => k.replace(/_/g, " ")).join(", ") : "answer";
  }

  // An item's determinacy in one cell: "determined", or what is not and the warnings' codes.
  function determinacy(item) {
    const d = item && item.determinacy;
    const warnings = [...((d && d.warnings) || []), ...((item && item.warnings) || [])].map((w) => (w && w.code) || String(w));
    if (!d && !warnings.length) return null;
    const notDetermined = d && d.determined === false;
    const text = [notDetermined ? "not determined" : "determined", ...warnings].join(", ");
    return {text, bad: notDetermined || warnings.length > 0};
  }

  function figure(label, content, note) {
    return el("div", {}, el("dt", {text: label}), el("dd", {}, content), note ? el("dd", {class: "note", text: note}) : null);
  }

  function badge(ok, yes, no) { return el("span", {class: `status ${ok ? "yes" : "no"}`, text: ok ? yes : no}); }

  // The intrinsics read off a K, each against the ranges solved with: a value on a range's end
  // means the ranges excluded what the data wanted (docs/kinds.md, "The direct method").
  function intrinsics(K, ranges) {
    const values = {focal_x: K[0][0], focal_y: K[1][1], aspect: K[1][1] / K[0][0], skew: K[0][1], principal_u: K[0][2],
                    principal_v: K[1][2]};
    const range = (name) => {
      if (!ranges) return null;
      if (name === "focal_x") return ranges.focal;
      if (name === "focal_y") return null;  // the focal range times the aspect's: not a range of its own
      if (name === "principal_u") return ranges.principal_point && ranges.principal_point[0];
      if (name === "principal_v") return ranges.principal_point && ranges.principal_point[1];
      return ranges[name];
    };
    return Object.entries(values).map(([name, v]) => {
      const r = range(name);
      let note = null;
      if (Array.isArray(r) && r.length === 2) {
        const span = Math.abs(r[1] - r[0]) || 1, edge = Math.min(Math.abs(v - r[0]), Math.abs(v - r[1])) <= 1e-3 * span;
        note = v < r[0] - 1e-6 * span || v > r[1] + 1e-6 * span ? "outside its range" : edge ? "at its range's end" : null;
        return {name, value: v, range: r, note};
      }
      return {name, value: v, range: null, note};
    });
  }

  function intrinsicsTable(K, ranges, intervals) {
    const interval = (name) => (intervals || []).find((i) => i.name === name);
    const rows = intrinsics(K, ranges).map((r) => {
      const i = interval(r.name);
      const determined = i ? (i.lower === null || i.upper === null ? "not at all (unbounded)" : `${fmt(i.lower)} to ${fmt(i.upper)}`) : "—";
      return el("tr", {"data-intrinsic": r.name, class: r.note || (i && (i.lower === null || i.upper === null)) ? "flagged" : null},
        el("td", {text: r.name.replace("_", " ")}), el("td", {class: "num", text: fmt(r.value)}),
        el("td", {class: "num", text: r.range ? `${fmt(r.range[0])} to ${fmt(r.range[1])}` : "—"}),
        el("td", {class: "num", text: determined}), el("td", {text: r.note || ""}));
    });
    return el("div", {class: "table-wrap"}, el("table", {class: "compact"},
      el("thead", {}, el("tr", {}, ["", "value", "range solved with", "data fix it within", ""].map((h, k) =>
        el("th", {class: k && k < 4 ? "num" : null, text: h})))), el("tbody", {}, rows)));
  }

  // --- per kind ----------------------------------------------------------------------------------
  function autocalibration(result) {
    const parts = [], figures = [];
    const stages = result.stages || [];
    const last = stages[stages.length - 1] || {};
    const det = last.determinacy || null;
    figures.push(figure("Method", result.method || "—"));
    for (const s of stages) {
      const d = s.determinacy;
      figures.push(figure(`Stage ${s.name}`, el("span", {}, badge(s.certified, "certified", "not certified"), " ",
        d ? badge(d.determined, "determined", "not determined") : ""), `${s.status}${s.reason ? ": " + s.reason : ""}`));
    }
    parts.push(el("dl", {class: "stats"}, figures));
    if (isMatrix(result.K)) {
      const from = `from the ${last.name || "last"} stage: ${last.certified ? "certified" : "NOT certified"}` +
                   (det ? (det.determined ? ", determined by the data" : ", NOT determined by the data") : "");
      parts.push(el("h3", {text: "K"}), el("p", {class: `note ${last.certified && (!det || det.determined) ? "" : "flag"}`, id: "k-note", text: from}),
                 matrix(result.K), intrinsicsTable(result.K, result.intrinsics, det && det.intervals));
    } else if (Array.isArray(result.Ks)) {
      parts.push(el("h3", {text: "K of each view"}), el("ul", {class: "plain"},
        result.Ks.map((K, i) => el("li", {}, `view ${i}: `, K ? `focal ${fmt(K[0][0])} px` : "—"))));
    } else {
      parts.push(el("p", {class: "note flag", id: "k-note", text: "No K: no stage found a calibration."}));
    }
    if (isVector(result.plane_at_infinity)) parts.push(el("p", {}, "Plane at infinity (input frame): ", vector(result.plane_at_infinity)));
    if (result.baseline && isMatrix(result.baseline.K)) {
      parts.push(el("details", {}, el("summary", {text: "The linear method's K (the thesis's baseline; not certified)"}),
        matrix(result.baseline.K), el("p", {class: "note", text: `positive semidefinite: ${result.baseline.psd ? "yes" : "no"}; cost ${fmt(result.baseline.cost)}`})));
    }
    return parts;
  }

  function reconstruction(result) {
    const s = result.summary || {};
    const stages = result.stages || [];
    const registered = (result.cameras || []).filter((c) => c && c.registered);
    const figures = [
      figure("Views registered", `${s.views_registered ?? registered.length} of ${s.views ?? (result.cameras || []).length}`),
      figure("Points", `${num(s.points ?? (result.points || []).length)} of ${num(s.tracks)} tracks`),
      figure("Points certified", `${num(s.points_certified)} of ${num(s.points)}`),
      figure("Cameras certified", `${num(s.cameras_certified)} of ${num(s.views_registered)}`),
      figure("RMS reprojection", s.rms_reprojection_px === undefined ? "—" : `${fmt(s.rms_reprojection_px)} px`),
      figure("Observations", num(s.observations)),
    ];
    const auto = stages.find((st) => st && st.name === "autocalibration");
    if (auto) {
      const d = auto.determined;
      figures.push(figure("Metric upgrade", el("span", {}, auto.status === "skipped" ? el("span", {class: "status", text: "skipped"})
        : badge(auto.certified, "certified", "not certified"), " ", d === false ? badge(false, "", "not determined") : d ? badge(true, "determined", "") : ""),
        auto.reason || (s.critical_motion ? `critical motion: ${s.critical_motion}` : null)));
    }
    const parts = [el("dl", {class: "stats"}, figures)];
    // K as returned (the cameras'), and where it came from: it is the adjustment's, not a certificate's
    const Ks = registered.map((c) => c.K).filter(isMatrix);
    const shared = Ks.length && Ks.every((K) => JSON.stringify(K) === JSON.stringify(Ks[0]));
    if (Ks.length) {
      const adjusted = stages.find((st) => st && st.name === "bundle_adjustment" && st.status === "done");
      const origin = adjusted && adjusted.model === "fixed" ? "the K given (options.intrinsics), held fixed"
        : adjusted ? `from the metric bundle adjustment (camera model ${adjusted.model || "—"}): an estimate, not certified`
        : "not certified";
      parts.push(el("h3", {text: shared ? "K (every registered view)" : "K (view 0 of the registered; it varies per view)"}),
                 el("p", {class: adjusted && adjusted.model === "fixed" ? "note" : "note flag", id: "k-note", text: origin}),
                 matrix(Ks[0]));
      if (auto && isMatrix(auto.K)) {
        parts.push(el("details", {}, el("summary", {text: `The autocalibration stage's K (${auto.certified ? "certified upgrade" : "not certified"}` +
                                                            `${auto.determined === false ? ", not determined by the data" : ""})`}), matrix(auto.K)));
      }
    }
    parts.push(el("h3", {text: "Cameras"}), camerasTable(result.cameras || []));
    parts.push(el("h3", {text: "Stages"}), el("div", {class: "table-wrap"}, el("table", {class: "compact", id: "stages"},
      el("thead", {}, el("tr", {}, ["stage", "status", "time", "reason"].map((h) => el("th", {text: h})))),
      el("tbody", {}, stages.map((st) => el("tr", {"data-stage": st.name},
        el("td", {text: st.name}), el("td", {}, el("span", {class: `status ${st.status}`, text: st.status})),
        el("td", {class: "num", text: GC.duration(st.elapsed_s)}), el("td", {class: "reason", text: st.reason || ""})))))));
    return parts;
  }

  // Each view's camera and the bound stated for it (a shared K is a constraint the free
  // resection does not have, so a camera is often reported with its gap, not certified).
  function camerasTable(cameras) {
    const head = ["view", "name", "registered", "certified", "status", "cost", "lower bound", "gap", "focal", "reason"];
    const rows = cameras.map((c) => el("tr", {"data-view": c.view, class: c.registered && !c.certified ? "flagged" : null},
      el("td", {class: "num", text: c.view}), el("td", {text: c.name || ""}), el("td", {text: c.registered ? "yes" : "no"}),
      el("td", {text: c.certified ? "yes" : "no"}), el("td", {}, el("span", {class: `status ${c.status}`, text: c.status || "—"})),
      el("td", {class: "num", text: fmt(c.cost)}), el("td", {class: "num", text: fmt(c.lower_bound)}),
      el("td", {class: "num", text: fmt(c.gap)}), el("td", {class: "num", text: isMatrix(c.K) ? fmt(c.K[0][0]) : "—"}),
      el("td", {class: "reason", title: c.reason || c.bound_reason || null, text: c.reason || c.bound_reason || ""})));
    return el("div", {class: "table-wrap"}, el("table", {class: "compact", id: "cameras"},
      el("thead", {}, el("tr", {}, head.map((h, k) => el("th", {class: [0, 5, 6, 7, 8].includes(k) ? "num" : null, text: h})))),
      el("tbody", {}, rows)));
  }

  function stereoLines(result) {
    const pairs = result.pairs || [];
    const failed = pairs.filter((p) => p && p.status !== "estimate").length;
    const figures = [figure("Solver", result.solver || "—"), figure("Frame pairs", `${pairs.length}${failed ? `, ${failed} failed` : ""}`)];
    const last = (result.trajectory || []).filter(Boolean).pop();
    if (last && isVector(last.center)) figures.push(figure("Last frame's centre", vector(last.center), "in frame 0's left camera coordinates"));
    return [el("dl", {class: "stats"}, figures)];
  }

  function generic(result) {
    const figures = [];
    for (const [key, v] of Object.entries(result)) {
      if (["kind", "stats"].includes(key) || v === null || (typeof v === "object" && !isMatrix(v) && !isVector(v))) continue;
      figures.push(figure(key.replace(/_/g, " "), value(v)));
    }
    return figures.length ? [el("dl", {class: "stats"}, figures)] : [];
  }

  function figures(kind, result) {
    if (kind === "autocalibration") return autocalibration(result);
    if (kind === "reconstruction") return reconstruction(result);
    if (kind === "stereo_lines") return stereoLines(result);
    return generic(result);
  }

  // Exports a finished reconstruction offers (GET /v1/jobs/{id}/export).
  function exports(job) {
    if (job.kind !== "reconstruction" || job.status !== "succeeded") return [];
    const base = `/v1/jobs/${encodeURIComponent(job.id)}/export`;
    return [["COLMAP model (zip)", `${base}?format=colmap`, `${job.id}-colmap.zip`],
            ["Points (PLY)", `${base}?format=ply`, `${job.id}.ply`],
            ["Points (binary PLY)", `${base}?format=ply&binary=true`, `${job.id}-binary.ply`]];
  }

  return {solution, hasSolution, solutionLabel, determinacy, figures, exports, matrix, vector, value};
})();
