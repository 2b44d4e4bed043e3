// What a result proves and what it does not, read generically: every boolean `certified` (and
// `*_certified`), every `determined: false` (and `*_determined`) and every `warnings` list found
// anywhere in the result is collected and grouped, so the page can say first what is not
// certified, not determined or warned about, whatever kind the result is and whatever fields a
// kind adds later. Certificates, proofs and observations are not read (they hold no verdicts).
"use strict";

const Truth = (() => {
  const SKIP = new Set(["certificate", "camera_certificate", "proof", "root_region", "observations", "intervals",
                        "images", "baseline"]);
  const words = (key) => key.replace(/_/g, " ");

  // A list of numbers (or of lists of numbers): a point, a matrix; nothing to read inside.
  function numeric(list) {
    const first = list.find((v) => v !== null);
    return first === undefined || typeof first === "number" || (Array.isArray(first) && numeric(first));
  }

  // An entry of a list, for saying which one: its own name, else its view, else its index.
  function nameOf(owner) {
    if (typeof owner === "string") return owner;  // a path outside lists
    const node = owner.node;
    if (node && typeof node.name === "string" && node.name) return node.name;
    if (node && Number.isInteger(node.view)) return `view ${node.view}`;
    return `#${owner.index}`;
  }

  function warningOf(w) {
    if (typeof w === "string") return {code: w, detail: ""};
    if (w && typeof w === "object") return {code: String(w.code || w.name || "warning"), detail: String(w.detail || w.message || "")};
    return {code: String(w), detail: ""};
  }

  // Walks the result once. pattern: the path with list indices as "*" (what groups entries);
  // where: the path outside lists (what a flag there is called); owner: the list entry a value
  // sits in ({index, node}; its name is made only when shown). Strings are built per list and
  // per key, never per entry: 10^5 tracks are walked in well under a second.
  function scan(result) {
    const groups = new Map();   // pattern -> {label, entries: [{owner, certified, status, reason}]}
    const flags = [];           // {where, key}: "*_certified" false outside lists of entries
    const undetermined = new Map();  // pattern -> {label, where: [owner or path]}
    const warnings = new Map();      // pattern + code -> {code, detail, label, where: [owner or path]}

    function group(map, pattern, label) {
      let g = map.get(pattern);
      if (!g) map.set(pattern, g = {label, entries: [], where: []});
      return g;
    }

    function visit(node, pattern, where, label, owner) {
      if (Array.isArray(node)) {
        if (numeric(node)) return;
        const inner = pattern + "/*";
        for (let i = 0; i < node.length; i++) {
          if (node[i] && typeof node[i] === "object") visit(node[i], inner, null, label, {index: i, node: node[i]});
        }
        return;
      }
      if (typeof node.certified === "boolean" && owner) {
        group(groups, pattern, label).entries.push({owner, certified: node.certified, status: node.status,
                                                    unregistered: node.registered === false});
      }
      for (const key in node) {
        const value = node[key];
        if (value === false) {
          if (key === "determined" || key.endsWith("_determined")) {
            group(undetermined, pattern + "/" + key, key === "determined" ? label
              : `${label ? label + ": " : ""}${words(key.replace(/_determined$/, ""))}`).where.push(owner || where);
          } else if (key.endsWith("_certified")) flags.push({where, key, node});
          continue;
        }
        if (value === null || typeof value !== "object" || SKIP.has(key)) continue;
        if (Array.isArray(value) && (key === "warnings" || key.endsWith("_warnings"))) {
          for (const w of value) {
            const {code, detail} = warningOf(w);
            const g = group(warnings, `${pattern}|${code}`, label);
            g.code = code;
            if (!g.detail) g.detail = detail;
            g.where.push(owner || where);
          }
          continue;
        }
        // a list's label is its key, qualified by the entry it sits in when nested (autocalibration stages)
        const list = Array.isArray(value);
        const next = list && !numeric(value) ? (owner && label ? `${nameOf(owner)} ${words(key)}` : words(key)) : label;
        visit(value, pattern + "/" + key, where === null ? null : where + "/" + key, next, list ? null : owner);
      }
    }

    visit(result, "", "", "", null);
    return {groups: [...groups.entries()].map(([pattern, g]) => ({pattern, ...g})),
            flags, undetermined: [...undetermined.values()], warnings: [...warnings.values()]};
  }

  // The first few of a list of entries (or names), and how many there are.
  function listNames(entries, total, limit = 6) {
    const unique = [...new Set(entries)];
    const shown = unique.slice(0, limit).map(nameOf).join(", ");
    return unique.length > limit ? `${shown}, … (${unique.length}${total ? " of " + total : ""})` : shown;
  }

  // What an entry's status word means, for one not certified (the word itself follows in brackets).
  const STATUS_WORDS = {
    not_run: "not judged: no bound was computed for it",
    not_certified: "judged: its bound did not reach the tolerance",
    degenerate: "too few certified points to bound it",
  };
  const statusSaid = (status) => (STATUS_WORDS[status] ? `${STATUS_WORDS[status]}, status ${status}` : status);

  // Where the returned K came from (summary.calibration.source), in words.
  const SOURCES = {
    bundle_adjustment: "the bundle adjustment's estimate",
    camera_model: "the camera model's (the certified K with square pixels and the principal point at the centre)",
    given: "the K given with the job", none: "none",
  };

  // A flag "*_certified": false, said plainly. ``node`` is the object that states it.
  function flagText(key, node) {
    if (key === "returned_is_certified") {
      const source = node && SOURCES[node.source] ? `: it is ${SOURCES[node.source]}` : "";
      const certified = node && node.certified ? "; the autocalibration's certified K is shown apart" : "";
      return `The K the cameras use is not certified${source}${certified}`;
    }
    return `${words(key.replace(/_certified$/, ""))}: not certified`;
  }

  // How many views the views_not_registered line names, as the warning itself does
  // (claims.VIEWS_NAMED): a 500-photo job's would be a wall of names; the rest are counted, and
  // the cameras table (and the JSON) still lists every view with its reason.
  const VIEWS_NAMED = 10;

  // views_not_registered names its views by index; with the job's photos named, by their names.
  function unregisteredDetail(result, w) {
    const cameras = Array.isArray(result.cameras) ? result.cameras.filter((c) => c && typeof c === "object") : [];
    const missing = cameras.filter((c) => c.registered === false);
    if (!missing.length || !missing.some((c) => typeof c.name === "string" && c.name)) return w.detail;
    const why = new Map();
    for (const c of missing.slice(0, VIEWS_NAMED)) {
      const reason = c.reason || "no reason recorded";
      if (!why.has(reason)) why.set(reason, []);
      why.get(reason).push(typeof c.name === "string" && c.name ? c.name : `view ${c.view}`);
    }
    const more = missing.length > VIEWS_NAMED
      ? `; and ${missing.length - VIEWS_NAMED} more (the cameras table lists every view and its reason)` : "";
    return `${missing.length} of ${cameras.length} views not registered (no camera returned for them): ` +
           [...why].map(([reason, names]) => `${names.join(", ")}: ${reason}`).join("; ") + more;
  }

  // The verdict: {level: "yes" | "warn" | "no" | "estimate" | "failed", headline, lines: [{level, text}]}
  // itemKey: the kind's list of claims (tracks, maps, stages, points, frames, pairs).
  function verdict(job, result, itemKey, certifies) {
    const lines = [];
    if (!result) {
      return {level: "no", lines, headline: job.status === "failed" ? "Failed: this job returned no answer."
                                                                   : `${job.status[0].toUpperCase()}${job.status.slice(1)}: no result.`};
    }
    const found = scan(result);
    const main = found.groups.find((g) => g.pattern === `/${itemKey}/*`);
    const others = found.groups.filter((g) => g !== main);
    // "6 of 14 cameras certified; 8 not registered (no camera was returned for them): a.jpg, ...;
    // not certified: box0.jpg (judged: its bound did not reach the tolerance (not_certified))"
    // (reasons are in the tables). An entry not registered is said so, not by its status word.
    const describe = (g) => {
      const n = g.entries.length, missing = g.entries.filter((e) => !e.certified), yes = n - missing.length;
      const only = n === 1 ? nameOf(g.entries[0].owner) : null;  // one named entry: say which
      if (!missing.length) return only && !only.startsWith("#") ? `${g.label.replace(/s$/, "")} ${only}: certified`
                                                               : `${yes} of ${n} ${g.label} certified`;
      const unregistered = missing.filter((e) => e.unregistered), judged = missing.filter((e) => !e.unregistered);
      const some = (entries) => `${entries.slice(0, 6).map((e) => nameOf(e.owner)).join(", ")}${entries.length > 6 ? `, … (${entries.length})` : ""}`;
      const parts = [`${yes} of ${n} ${g.label} certified`];
      if (unregistered.length) {
        parts.push(`${unregistered.length} not registered (no camera was returned for them, so none is certified): ${some(unregistered)}`);
      }
      if (judged.length && !yes && judged.length > 6) {
        const statuses = new Map();
        for (const e of judged) statuses.set(e.status || "no status", (statuses.get(e.status || "no status") || 0) + 1);
        parts.push(`not certified: ${[...statuses].map(([status, count]) => `${count} ${statusSaid(status)}`).join(", ")}`);
      } else if (judged.length) {
        const named = judged.slice(0, 6).map((e) => `${nameOf(e.owner)}${e.status ? ` (${statusSaid(e.status)})` : ""}`).join(", ");
        parts.push(`not certified: ${named}${judged.length > 6 ? `, … (${judged.length})` : ""}`);
      }
      return parts.join("; ");
    };
    let allCertified = true, noneCertified = true, anyClaims = false;
    for (const g of [main, ...others].filter(Boolean)) {
      const yes = g.entries.filter((e) => e.certified).length;
      anyClaims = anyClaims || g.entries.length > 0;
      if (yes < g.entries.length) allCertified = false;
      if (g === main && yes > 0) noneCertified = false;
      if (certifies !== false) lines.push({level: yes === g.entries.length ? "yes" : yes ? "warn" : "no", text: describe(g), kind: "certified"});
    }
    const stages = Array.isArray(result.stages) ? result.stages : [];
    for (const f of found.flags) {
      const subject = f.key.replace(/_certified$/, "");
      const stage = stages.find((s) => s && s.name === subject && s.status && !["done", "optimal"].includes(s.status));
      if (stage) lines.push({level: "info", text: `${words(subject)}: ${stage.status}${stage.reason ? ` (${stage.reason})` : ""}`, kind: "flag"});
      else {
        allCertified = false;
        lines.push({level: "no", text: flagText(f.key, f.node), kind: "flag"});
      }
    }
    // "see the warnings" only where the result carries some: a stereo pair's translation is
    // undetermined with no warning, and the page sent the reader to look for one that is not there
    const seeWarnings = found.warnings.length ? "; see the warnings" : "";
    for (const u of found.undetermined) {
      lines.push({level: "warn", kind: "determined",
                  text: `Not determined by the data: ${u.label ? u.label + " " : ""}${listNames(u.where)}` +
                        ` (the answer is one of many that fit as well${seeWarnings})`});
    }
    for (const w of found.warnings) {
      const detail = w.code === "views_not_registered" ? unregisteredDetail(result, w) : w.detail;
      lines.push({level: "warn", kind: "warning",
                  text: `Warning ${w.code}${w.label ? ` (${w.label} ${listNames(w.where)})` : ""}${detail ? ": " + detail : ""}`});
    }
    const troubled = found.undetermined.length + found.warnings.length > 0;
    let level, headline;
    const cancelled = job.status === "cancelled" ? "Cancelled: what finished is kept. "
                    : job.status === "failed" ? "Failed: what finished before the failure is kept. " : "";
    if (certifies === false) {
      level = "estimate";
      headline = `${cancelled}Estimates, not certified: this kind returns estimates with their statistics; nothing in this result is proven.`;
    } else if (!anyClaims) {
      level = "no";
      headline = `${cancelled}Nothing in this result is certified.`;
    } else if (allCertified && !troubled) {
      level = cancelled ? "warn" : "yes";
      headline = cancelled ? `${cancelled}Everything it returned is certified.`
                           : "Certified: every answer below is proven optimal within its tolerance.";
    } else if (allCertified) {
      level = "warn";
      headline = `${cancelled}Certified optimum, but read ${found.warnings.length ? "the warnings" : "what is not determined"}: ` +
                 "the data may not fix the answer.";
    } else if (noneCertified && main) {
      level = "no";
      headline = `${cancelled}Not certified: no ${main.label.replace(/s$/, "")} has a proven bound within its tolerance.`;
    } else {
      level = "warn";
      headline = `${cancelled}Partly certified: see what is not.`;
    }
    return {level, headline, lines, found};
  }

  return {scan, verdict};
})();
