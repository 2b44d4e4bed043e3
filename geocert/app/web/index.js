// "/": the caller's jobs, newest first, and a form to submit one.
"use strict";

(() => {
  const {el, num, duration} = GC;
  const state = {jobs: [], cursor: null, kinds: [], timer: null};

  function kindInfo(name) { return state.kinds.find((k) => k.kind === name); }

  async function loadKinds() {
    state.kinds = await GC.json("/v1/problems");
    const select = document.getElementById("template-kind");
    for (const kind of state.kinds) select.append(el("option", {value: kind.kind, text: `${kind.kind} — ${kind.description}`.slice(0, 90)}));
    const images = state.kinds.find((k) => k.kind === "reconstruction" &&
                                          JSON.stringify(k.request_schema).includes("images"));
    const radio = document.getElementById("source-images");
    radio.disabled = !images;
    document.getElementById("images-note").textContent = images
      ? "Images are sent as a reconstruction job (matches found by the service)."
      : "Images: needs the reconstruction kind, which this service does not serve yet.";
  }

  // A kind's template is its example job, as /v1/problems gives it: it runs as given.
  function template(name) {
    const info = kindInfo(name);
    if (!info) return;
    const job = info.example || {kind: name, data: {}, options: {}};
    document.getElementById("job-json").value = JSON.stringify(job, null, 2);
  }

  function source() { return document.querySelector("input[name=source]:checked").value; }

  function showSource() {
    const s = source();
    document.getElementById("paste-part").hidden = s !== "paste";
    document.getElementById("upload-part").hidden = s !== "upload";
    document.getElementById("images-part").hidden = s !== "images";
  }

  function readFile(file, asDataUrl) {
    return new Promise((resolve, reject) => {
      const reader = new FileReader();
      reader.onload = () => resolve(reader.result);
      reader.onerror = () => reject(reader.error);
      if (asDataUrl) reader.readAsDataURL(file); else reader.readAsText(file);
    });
  }

  async function jobBody() {
    const s = source();
    let text;
    if (s === "paste") text = document.getElementById("job-json").value;
    else if (s === "upload") {
      const file = document.getElementById("job-file").files[0];
      if (!file) throw new Error("Choose a JSON file to upload.");
      text = await readFile(file, false);
    } else {
      const files = [...document.getElementById("image-files").files];
      if (files.length < 2) throw new Error("Choose at least two images.");
      const images = [];
      for (const file of files) {
        const url = await readFile(file, true);
        images.push({name: file.name, content: url.slice(url.indexOf(",") + 1)});
      }
      return JSON.stringify({kind: "reconstruction", data: {images}, options: {}});
    }
    try {
      JSON.parse(text);
    } catch (error) {
      throw new Error(`Not JSON: ${error.message}`);
    }
    return text;
  }

  async function submit(event) {
    event.preventDefault();
    const status = document.getElementById("submit-status");
    const button = document.getElementById("submit-button");
    GC.showError(null);
    button.disabled = true;
    status.textContent = "Submitting…";
    try {
      const body = await jobBody();
      const job = await GC.json("/v1/jobs", {method: "POST", body, headers: {"Content-Type": "application/json"}});
      status.textContent = `Job ${job.id} queued.`;
      window.location.assign(`/jobs/${job.id}`);
    } catch (error) {
      status.textContent = "";
      GC.showError(error);
    } finally {
      button.disabled = false;
    }
  }

  // Whether a kind's job items are its data's own list (tracks, maps, frames), one claim each; a
  // reconstruction or an autocalibration is one job item whose claims (points, cameras, stages)
  // one flag does not describe.
  function itemsAreClaims(info) {
    const schema = info.request_schema || {};
    const ref = schema.properties && schema.properties.data && schema.properties.data.$ref;
    const data = ref ? ref.replace(/^#\//, "").split("/").reduce((node, part) => node && node[part], schema) : null;
    return Boolean(data && data.properties && info.item_name in data.properties);
  }

  // The certified fraction of a job's items. A kind of estimates certifies nothing; a job whose
  // one item is the whole reconstruction has its page say what is certified and what is not.
  function certifiedCell(job) {
    const p = job.progress || {};
    const total = p.items_total || 0;
    const info = kindInfo(job.kind);
    if (info && info.certifies === false) return {text: "estimates", title: "this kind returns estimates, not certificates"};
    if (p.items_certified === null || p.items_certified === undefined || !total) return {text: "—"};
    if (info && !itemsAreClaims(info)) return {text: "see job", title: `its ${info.item_name} and what the data do not fix are on its page`};
    return {text: `${(100 * p.items_certified / total).toFixed(total >= 1000 ? 1 : 0)} %`};
  }

  function row(job) {
    const p = job.progress || {};
    const total = p.items_total || 0;
    const certified = certifiedCell(job);
    return el("tr", {"data-job": job.id},
      el("td", {}, el("a", {href: `/jobs/${job.id}`, text: job.id.slice(0, 12), title: job.id})),
      el("td", {text: job.kind}),
      el("td", {}, el("span", {class: `status ${job.status}`, text: job.status})),
      el("td", {class: "num", text: `${p.items_done || 0} / ${total}`}),
      el("td", {class: "num", text: certified.text, title: certified.title || null}),
      el("td", {class: "num", text: duration(GC.elapsed(job))}),
      el("td", {class: "hide-narrow", text: new Date(job.created_at * 1000).toLocaleString()}));
  }

  function render() {
    const body = document.querySelector("#jobs tbody");
    body.replaceChildren(...state.jobs.map(row));
    if (!state.jobs.length) body.append(el("tr", {}, el("td", {colspan: 7, class: "note", text: "No jobs yet."})));
    document.getElementById("more").hidden = !state.cursor;
  }

  async function load(append) {
    const limit = append ? 20 : Math.min(100, Math.max(20, state.jobs.length));
    const query = new URLSearchParams({limit: String(limit)});
    if (append && state.cursor) query.set("cursor", state.cursor);
    const page = await GC.json(`/v1/jobs?${query}`);
    if (append) state.jobs = state.jobs.concat(page.jobs);
    else state.jobs = page.jobs;
    if (append || state.jobs.length <= limit) state.cursor = page.next_cursor;
    render();
    document.getElementById("jobs-note").textContent = `Updated ${new Date().toLocaleTimeString()}`;
    clearTimeout(state.timer);
    if (state.jobs.some((job) => !GC.TERMINAL.has(job.status)))
      state.timer = setTimeout(() => load(false).catch(GC.showError), 2000);
  }

  document.addEventListener("DOMContentLoaded", () => {
    document.getElementById("submit-form").addEventListener("submit", submit);
    for (const radio of document.querySelectorAll("input[name=source]")) radio.addEventListener("change", showSource);
    document.getElementById("template-kind").addEventListener("change", (e) => template(e.target.value));
    document.getElementById("refresh").addEventListener("click", () => load(false).catch(GC.showError));
    document.getElementById("more").addEventListener("click", () => load(true).catch(GC.showError));
    showSource();
    loadKinds().then(() => load(false)).catch(GC.showError);
  });
})();
