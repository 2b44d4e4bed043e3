// Canvas drawings: the bound chart (log scale), a histogram, and a 3D view of points and cameras
// (a perspective projection drawn in 2D: drag or arrow keys to rotate, wheel or +/- to zoom).
"use strict";

const Charts = (() => {
  const css = (name) => getComputedStyle(document.documentElement).getPropertyValue(name).trim() || "#333";

  function niceExp(value) { return Math.floor(Math.log10(value)); }

  // A stage's name without its count ("structure 2450/4983" -> "structure").
  const stageName = (stage) => (stage ? String(stage).replace(/\s*\d+\s*\/\s*\d+\s*$/, "") : "");

  // Upper bound, lower bound and gap over time, on a log scale (values <= 0 are not drawable and
  // skipped), with a marker where a staged solve's stage changes (each stage bounds its own cost).
  class BoundChart {
    constructor(canvas) {
      this.canvas = canvas;
      this.points = [];  // {t, upper, lower, gap, stage}
      this.pending = false;
      this.ended = null;  // the message to show when a finished job reported no bounds
      window.addEventListener("resize", () => this.draw());
    }

    add(t, upper, lower, gap, stage) {
      const same = (p) => p.t === t && p.upper === upper && p.lower === lower && p.gap === gap;
      if (this.points.slice(-3).some(same)) return;
      this.points.push({t, upper, lower, gap, stage: stageName(stage)});
      const last = this.points[this.points.length - 2];
      if (last && t < last.t) this.points.sort((a, b) => a.t - b.t);
      this.canvas.dataset.points = String(this.points.length);
      this.schedule();
    }

    schedule() {
      if (!this.pending) {
        this.pending = true;
        requestAnimationFrame(() => { this.pending = false; this.draw(); });
      }
    }

    // The job has ended: no more points will come.
    finish(message) {
      this.ended = message;
      this.canvas.dataset.ended = "true";
      this.schedule();
    }

    drawable() {
      return this.points.filter((p) => ["upper", "lower", "gap"].some((k) => p[k] > 0 && Number.isFinite(p[k])));
    }

    // In words, for the note under the chart.
    summary() {
      const n = this.drawable().length;
      if (!n) return "";
      const last = this.points[this.points.length - 1];
      const stages = [...new Set(this.points.map((p) => p.stage).filter(Boolean))];
      return `${n} progress report${n === 1 ? "" : "s"} with bounds over ${last.t.toFixed(1)} s` +
             (n === 1 ? " (the job ended within one report's interval)" : "") +
             (stages.length > 1 ? `; stages: ${stages.join(", ")} (each bounds its own cost)` : "") + ".";
    }

    draw() {
      const {ctx, width, height} = GC.fitCanvas(this.canvas);
      ctx.clearRect(0, 0, width, height);
      // the upper bound drawn last, dashed: near the end it lies on the lower bound
      const series = [["gap", css("--gap")], ["lower", css("--lower")], ["upper", css("--upper")]];
      const values = [];
      for (const p of this.points) for (const [name] of series) if (p[name] > 0 && Number.isFinite(p[name])) values.push(p[name]);
      const left = 62, right = 12, top = 10, bottom = 34;
      const w = width - left - right, h = height - top - bottom;
      ctx.font = "12px system-ui, sans-serif";
      ctx.fillStyle = css("--muted");
      if (!values.length) {
        ctx.fillText(this.ended || "Waiting for progress…", left, top + 20);
        this.canvas.setAttribute("aria-label", this.ended || "Waiting for progress");
        return;
      }
      // (loops, not Math.min(...values): a long job's thousands of points would overflow the call's arguments)
      let least = Infinity, most = -Infinity;
      for (const v of values) { if (v < least) least = v; if (v > most) most = v; }
      let lo = niceExp(least), hi = niceExp(most) + 1;
      if (hi - lo < 1) hi = lo + 1;
      const t0 = 0, t1 = Math.max(1e-3, this.points[this.points.length - 1].t);  // points are kept in time order
      const x = (t) => left + w * (t - t0) / (t1 - t0);
      const y = (v) => top + h * (1 - (Math.log10(v) - lo) / (hi - lo));
      // grid and axes
      ctx.strokeStyle = "#e5e8eb";
      ctx.lineWidth = 1;
      const step = Math.max(1, Math.ceil((hi - lo) / 8));
      for (let e = lo; e <= hi; e += step) {
        const yy = y(10 ** e);
        ctx.beginPath(); ctx.moveTo(left, yy); ctx.lineTo(left + w, yy); ctx.stroke();
        ctx.fillText(`1e${e}`, 6, yy + 4);
      }
      for (let i = 0; i <= 4; i++) {
        const t = t0 + (t1 - t0) * i / 4, xx = x(t);
        ctx.beginPath(); ctx.moveTo(xx, top); ctx.lineTo(xx, top + h); ctx.stroke();
        ctx.fillText(`${t.toFixed(t1 < 10 ? 1 : 0)} s`, Math.min(xx - 10, width - 40), top + h + 16);
      }
      ctx.fillText("elapsed", left + w / 2 - 20, height - 4);
      // stage changes: a dashed line and the new stage's name
      ctx.save();
      ctx.strokeStyle = css("--muted");
      ctx.setLineDash([3, 3]);
      let previous = null, labelled = -Infinity;
      for (const p of this.points) {
        if (!p.stage || p.stage === previous) continue;
        const xx = x(p.t);
        if (previous !== null) { ctx.beginPath(); ctx.moveTo(xx, top); ctx.lineTo(xx, top + h); ctx.stroke(); }
        if (xx - labelled > 70) { ctx.fillText(p.stage, xx + 3, top + 12); labelled = xx; }
        previous = p.stage;
      }
      ctx.restore();
      for (const [name, color] of series) {
        ctx.strokeStyle = color;
        ctx.fillStyle = color;
        ctx.lineWidth = 2;
        ctx.setLineDash(name === "upper" ? [6, 4] : []);
        ctx.beginPath();
        let open = false;
        for (const p of this.points) {
          const v = p[name];
          if (!(v > 0) || !Number.isFinite(v)) { open = false; continue; }
          const xx = x(p.t), yy = y(v);
          if (open) ctx.lineTo(xx, yy); else ctx.moveTo(xx, yy);
          open = true;
        }
        ctx.stroke();
        ctx.setLineDash([]);
        for (const p of this.points) if (p[name] > 0 && Number.isFinite(p[name])) ctx.fillRect(x(p.t) - 2, y(p[name]) - 2, 4, 4);
      }
      const last = this.points[this.points.length - 1];
      this.canvas.setAttribute("aria-label", `Bounds over time, log scale: ${this.points.length} points; latest upper ` +
        `${GC.num(last.upper)}, lower ${GC.num(last.lower)}, gap ${GC.num(last.gap)} at ${last.t.toFixed(1)} s`);
    }
  }

  function histogram(canvas, values, unit) {
    const {ctx, width, height} = GC.fitCanvas(canvas);
    ctx.clearRect(0, 0, width, height);
    ctx.font = "12px system-ui, sans-serif";
    ctx.fillStyle = css("--muted");
    const finite = Float64Array.from(values.filter(Number.isFinite)).sort();  // a typed array sorts numerically, fast
    if (!finite.length) { ctx.fillText("No values.", 10, 20); return null; }
    const lo = Math.min(0, finite[0]);
    let hi = finite[Math.min(finite.length - 1, Math.floor(0.99 * (finite.length - 1)))];
    if (!(hi > lo)) hi = lo + 1;
    const bins = 30, counts = new Array(bins).fill(0);
    let over = 0;
    for (const v of finite) {
      if (v > hi) { over++; continue; }
      counts[Math.min(bins - 1, Math.floor((v - lo) / (hi - lo) * bins))]++;
    }
    const left = 48, right = 10, top = 10, bottom = 34, w = width - left - right, h = height - top - bottom;
    const max = Math.max(...counts);
    ctx.fillStyle = css("--accent");
    for (let i = 0; i < bins; i++) {
      const bh = h * counts[i] / max;
      ctx.fillRect(left + w * i / bins + 1, top + h - bh, w / bins - 2, bh);
    }
    ctx.fillStyle = css("--muted");
    ctx.fillText(String(max), 4, top + 10);
    ctx.fillText("0", 4, top + h);
    for (let i = 0; i <= 4; i++) ctx.fillText(GC.num(lo + (hi - lo) * i / 4, 2), left + w * i / 4 - (i === 4 ? 30 : 0), top + h + 16);
    ctx.fillText(unit, left, height - 4);
    const median = finite[Math.floor(finite.length / 2)];
    canvas.setAttribute("aria-label", `Histogram of ${finite.length} values (${unit}); median ${GC.num(median)}, ` +
                                      `largest ${GC.num(finite[finite.length - 1])}`);
    return {count: finite.length, median, max: finite[finite.length - 1], over, cut: hi};
  }

  // points: [[x, y, z]]; cameras: [{center: [x, y, z], axes: [right, down, forward] or null}]
  class View3D {
    constructor(canvas, points, cameras) {
      this.canvas = canvas;
      this.points = points;
      this.cameras = cameras;
      this.yaw = 0.6; this.pitch = -0.35; this.zoom = 1;
      // centred on the points' median; scaled so that 95% of the points and every camera fit
      const middle = points.length ? points : cameras.map((c) => c.center);
      const median = (k) => { const v = middle.map((p) => p[k]).sort((a, b) => a - b); return v[Math.floor(v.length / 2)] || 0; };
      this.centre = [median(0), median(1), median(2)];
      const away = (p) => Math.hypot(p[0] - this.centre[0], p[1] - this.centre[1], p[2] - this.centre[2]);
      const dist = points.map(away).sort((a, b) => a - b);
      const p95 = dist.length ? dist[Math.floor(0.95 * (dist.length - 1))] : 0;
      this.scale = Math.max(p95, ...cameras.map((c) => away(c.center))) || 1;
      this.bind();
      this.draw();
    }

    bind() {
      const c = this.canvas;
      let drag = null;
      c.addEventListener("pointerdown", (e) => { drag = {x: e.clientX, y: e.clientY}; c.setPointerCapture(e.pointerId); });
      c.addEventListener("pointermove", (e) => {
        if (!drag) return;
        this.rotate((e.clientX - drag.x) * 0.01, (e.clientY - drag.y) * 0.01);
        drag = {x: e.clientX, y: e.clientY};
      });
      const end = () => { drag = null; };
      c.addEventListener("pointerup", end);
      c.addEventListener("pointercancel", end);
      c.addEventListener("wheel", (e) => { e.preventDefault(); this.zoomBy(e.deltaY < 0 ? 1.15 : 1 / 1.15); }, {passive: false});
      c.addEventListener("keydown", (e) => {
        const moves = {ArrowLeft: [-0.1, 0], ArrowRight: [0.1, 0], ArrowUp: [0, -0.1], ArrowDown: [0, 0.1]};
        if (moves[e.key]) { e.preventDefault(); this.rotate(...moves[e.key]); }
        else if (e.key === "+" || e.key === "=") { e.preventDefault(); this.zoomBy(1.2); }
        else if (e.key === "-" || e.key === "_") { e.preventDefault(); this.zoomBy(1 / 1.2); }
      });
      window.addEventListener("resize", () => this.draw());
    }

    rotate(dyaw, dpitch) {
      this.yaw += dyaw;
      this.pitch = Math.max(-1.55, Math.min(1.55, this.pitch + dpitch));
      this.draw();
    }

    zoomBy(f) { this.zoom = Math.max(0.05, Math.min(200, this.zoom * f)); this.draw(); }

    reset() { this.yaw = 0.6; this.pitch = -0.35; this.zoom = 1; this.draw(); }

    draw() {
      const {ctx, width, height} = GC.fitCanvas(this.canvas);
      ctx.clearRect(0, 0, width, height);
      const cy = Math.cos(this.yaw), sy = Math.sin(this.yaw), cp = Math.cos(this.pitch), sp = Math.sin(this.pitch);
      const [ox, oy, oz] = this.centre, s = 1 / this.scale;
      const f = 2.6 * Math.min(width, height) * this.zoom, dist = 3.2;  // radius 1 fills about 0.8 of the view
      // world -> view: centre, scale, yaw about y, pitch about x; the eye at z = -dist looking along +z
      const project = (p) => {
        const x = (p[0] - ox) * s, y = (p[1] - oy) * s, z = (p[2] - oz) * s;
        const x1 = cy * x + sy * z, z1 = -sy * x + cy * z;
        const y2 = cp * y - sp * z1, z2 = sp * y + cp * z1 + dist;
        if (z2 < 0.05) return null;
        return [width / 2 + f * x1 / z2 / 2, height / 2 + f * y2 / z2 / 2];
      };
      ctx.fillStyle = "#3b4148";
      const size = this.points.length > 20000 ? 1.5 : 2.5;
      for (const p of this.points) {
        const q = project(p);
        if (q && q[0] >= 0 && q[1] >= 0 && q[0] <= width && q[1] <= height) ctx.fillRect(q[0] - size / 2, q[1] - size / 2, size, size);
      }
      ctx.strokeStyle = css("--gap");
      ctx.fillStyle = css("--gap");
      ctx.lineWidth = 1.5;
      const k = 0.08 * this.scale;
      for (const cam of this.cameras) {
        const c = project(cam.center);
        if (!c) continue;
        ctx.fillRect(c[0] - 3, c[1] - 3, 6, 6);
        if (!cam.axes) continue;
        const [r, d, fw] = cam.axes;
        const corner = (a, b) => [0, 1, 2].map((i) => cam.center[i] + k * (fw[i] * 1.5 + a * r[i] + b * d[i]));
        const corners = [[-1, -1], [1, -1], [1, 1], [-1, 1]].map(([a, b]) => project(corner(a, b)));
        if (corners.some((q) => !q)) continue;
        ctx.beginPath();
        for (const q of corners) { ctx.moveTo(c[0], c[1]); ctx.lineTo(q[0], q[1]); }
        ctx.moveTo(corners[3][0], corners[3][1]);
        for (const q of corners) ctx.lineTo(q[0], q[1]);
        ctx.stroke();
      }
      ctx.fillStyle = css("--muted");
      ctx.font = "12px system-ui, sans-serif";
      ctx.fillText(`${this.points.length} points, ${this.cameras.length} cameras`, 8, height - 8);
    }
  }

  return {BoundChart, histogram, View3D};
})();
