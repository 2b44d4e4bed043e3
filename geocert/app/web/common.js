// Shared by the pages: API calls with the caller's key, an event-stream reader, formatting.
// Plain browser JavaScript, no build step, nothing fetched from another site.
"use strict";

const GC = (() => {
  const KEY = "geocert.apiKey";
  let config = null;

  async function getConfig() {
    if (config === null) {
      const response = await fetch("/web/config.json", {cache: "no-store"});
      config = await response.json();
    }
    return config;
  }

  // Ask for the API key in the page's dialog; resolves once one is given (kept for the tab only).
  // Calls made while the dialog is open wait for the same answer: the page asks once.
  let asking = null;
  function askKey(message) {
    if (!asking) asking = showKeyDialog(message).finally(() => { asking = null; });
    return asking;
  }

  function showKeyDialog(message) {
    const dialog = document.getElementById("key-dialog");
    const form = dialog.querySelector("form");
    const input = dialog.querySelector("input");
    dialog.querySelector(".key-message").textContent = message || "This service needs an API key.";
    input.value = "";
    dialog.oncancel = (event) => event.preventDefault();  // Escape: every call needs the key, so the question stays
    return new Promise((resolve) => {
      form.onsubmit = (event) => {
        event.preventDefault();
        const key = input.value.trim();
        if (!key) return;
        sessionStorage.setItem(KEY, key);
        dialog.close();
        resolve(key);
      };
      dialog.showModal();
      input.focus();
    });
  }

  async function ensureKey() {
    const {keys_required} = await getConfig();
    if (keys_required && !sessionStorage.getItem(KEY)) await askKey();
  }

  function headers(extra) {
    const h = Object.assign({}, extra || {});
    const key = sessionStorage.getItem(KEY);
    if (key) h["X-API-Key"] = key;
    return h;
  }

  // fetch() a /v1 route with the key; a 401 or 403 asks for the key again and retries.
  async function api(path, options) {
    await ensureKey();
    const opts = Object.assign({}, options || {});
    const send = () => fetch(path, Object.assign({}, opts, {headers: headers(opts.headers)}));
    let response = await send();
    for (let tries = 0; (response.status === 401 || response.status === 403) && tries < 3; tries++) {
      sessionStorage.removeItem(KEY);
      await askKey(response.status === 403 ? "That key was refused; enter another." : "This service needs an API key.");
      response = await send();
    }
    return response;
  }

  async function json(path, options) {
    const response = await api(path, options);
    const body = await response.json().catch(() => null);
    if (!response.ok) throw new ApiError(response.status, body);
    return body;
  }

  class ApiError extends Error {
    constructor(status, body) {
      const detail = body && (body.detail || body.title);
      const fields = body && body.errors ? body.errors.map((e) => `${e.field}: ${e.reason}`).join("; ") : "";
      super(`${status}${detail ? ": " + (typeof detail === "string" ? detail : JSON.stringify(detail)) : ""}` +
            `${fields ? " (" + fields + ")" : ""}`);
      this.status = status;
      this.body = body;
    }
  }

  // Server-Sent Events over fetch (EventSource cannot send X-API-Key). Calls onEvent(name, data)
  // for each event; reconnects with Last-Event-ID until an "end" event or stop().
  function stream(path, onEvent) {
    let lastId = null, stopped = false, controller = null;
    async function run() {
      while (!stopped) {
        controller = new AbortController();
        let ended = false;
        try {
          const extra = {Accept: "text/event-stream"};
          if (lastId) extra["Last-Event-ID"] = lastId;
          const response = await api(path, {headers: extra, signal: controller.signal});
          if (!response.ok) throw new ApiError(response.status, await response.json().catch(() => null));
          const reader = response.body.getReader();
          const decoder = new TextDecoder();
          let buffer = "", event = {};
          for (;;) {
            const {value, done} = await reader.read();
            if (done) break;
            buffer += decoder.decode(value, {stream: true});
            let newline;
            while ((newline = buffer.indexOf("\n")) >= 0) {
              const line = buffer.slice(0, newline).replace(/\r$/, "");
              buffer = buffer.slice(newline + 1);
              if (line === "") {
                if (event.event) {
                  if (event.id) lastId = event.id;
                  const data = event.data ? JSON.parse(event.data) : null;
                  onEvent(event.event, data);
                  if (event.event === "end") ended = true;
                }
                event = {};
              } else if (!line.startsWith(":")) {
                const colon = line.indexOf(":");
                const field = colon < 0 ? line : line.slice(0, colon);
                const value = colon < 0 ? "" : line.slice(colon + 1).replace(/^ /, "");
                event[field] = field === "data" && event.data !== undefined ? event.data + "\n" + value : value;
              }
            }
          }
        } catch (error) {
          if (stopped || (error && error.name === "AbortError")) return;
          if (error instanceof ApiError && error.status < 500 && error.status !== 429) {
            onEvent("error", {message: error.message});
            return;
          }
        }
        if (ended) return;
        await new Promise((resolve) => setTimeout(resolve, 1000));
      }
    }
    run();
    return {stop() { stopped = true; if (controller) controller.abort(); }};
  }

  // A download through the API (the key goes in a header, so a plain link cannot carry it).
  async function download(path, filename) {
    const response = await api(path);
    if (!response.ok) throw new ApiError(response.status, await response.json().catch(() => null));
    const blob = await response.blob();
    const url = URL.createObjectURL(blob);
    const a = document.createElement("a");
    a.href = url;
    a.download = filename;
    document.body.appendChild(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(url), 10000);
  }

  function el(tag, attrs, ...children) {
    const node = document.createElement(tag);
    for (const [name, value] of Object.entries(attrs || {})) {
      if (value === null || value === undefined || value === false) continue;
      if (name === "class") node.className = value;
      else if (name === "text") node.textContent = value;
      else if (name.startsWith("on")) node.addEventListener(name.slice(2), value);
      else node.setAttribute(name, value === true ? "" : value);
    }
    for (const child of children.flat()) {
      if (child === null || child === undefined) continue;
      node.append(child instanceof Node ? child : String(child));
    }
    return node;
  }

  function num(value, digits) {
    if (value === null || value === undefined || Number.isNaN(value)) return "—";
    if (typeof value !== "number") return String(value);
    if (value === 0) return "0";
    const a = Math.abs(value);
    if (a >= 1e5 || a < 1e-3) return value.toExponential(digits === undefined ? 3 : digits);
    return Number(value.toPrecision(digits === undefined ? 5 : digits + 2)).toString();
  }

  function duration(seconds) {
    if (seconds === null || seconds === undefined) return "—";
    if (seconds < 60) return `${seconds.toFixed(1)} s`;
    const m = Math.floor(seconds / 60), s = Math.round(seconds % 60);
    if (m < 60) return `${m} min ${s} s`;
    return `${Math.floor(m / 60)} h ${m % 60} min`;
  }

  function elapsed(job) {
    if (job.progress && job.progress.elapsed_s && job.finished_at) return job.progress.elapsed_s;
    const start = job.started_at || job.created_at;
    if (!start) return null;
    const end = job.finished_at || Date.now() / 1000;
    return Math.max(0, end - start);
  }

  function showError(error) {
    const box = document.getElementById("error");
    if (!box) return;
    box.textContent = error ? String(error.message || error) : "";
    box.hidden = !error;
  }

  const TERMINAL = new Set(["succeeded", "failed", "cancelled"]);

  // A canvas sized to its box in device pixels; returns the 2D context scaled to CSS pixels.
  function fitCanvas(canvas) {
    const ratio = window.devicePixelRatio || 1;
    const width = Math.max(50, canvas.clientWidth), height = Math.max(50, canvas.clientHeight);
    if (canvas.width !== Math.round(width * ratio) || canvas.height !== Math.round(height * ratio)) {
      canvas.width = Math.round(width * ratio);
      canvas.height = Math.round(height * ratio);
    }
    const ctx = canvas.getContext("2d");
    ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
    return {ctx, width, height};
  }

  return {api, json, stream, download, el, num, duration, elapsed, showError, askKey, ApiError, TERMINAL,
          fitCanvas, keyName: KEY};
})();
