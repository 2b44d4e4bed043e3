// Geometry the page draws from a result: the 3D view's points and cameras, and per-observation
// residuals (a map's own, a reconstruction's observations through its returned cameras, or a
// triangulation's tracks reprojected through the request's cameras).
"use strict";

const Geometry = (() => {
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
    } else if (Array.isArray(result.trajectory) && result.trajectory.some((pose) => pose && Array.isArray(pose.center))) {
      cameras = result.trajectory.filter((pose) => pose && Array.isArray(pose.center)).map((pose) => ({  // a rig's path
        center: pose.center,
        axes: Array.isArray(pose.R) && pose.R.length === 3 ? [norm3(pose.R[0]), norm3(pose.R[1]), norm3(pose.R[2])] : null}));
    } else if (req && req.data && Array.isArray(req.data.cameras)) {
      cameras = req.data.cameras.map(cameraOf).filter(Boolean);
    }
    return {points, cameras};
  }

  // The pixel distance between an observation and a point's projection by P (null when P is missing).
  function reprojection(P, point, obs) {
    if (!Array.isArray(P) || P.length !== 3 || !Array.isArray(obs)) return null;
    const X = point.length === 4 ? point : [...point, 1];
    const [a, b, c] = P;
    const w = c[0] * X[0] + c[1] * X[1] + c[2] * X[2] + c[3] * X[3];
    if (!w) return null;
    const u = (a[0] * X[0] + a[1] * X[1] + a[2] * X[2] + a[3] * X[3]) / w - obs[0];
    const v = (b[0] * X[0] + b[1] * X[1] + b[2] * X[2] + b[3] * X[3]) / w - obs[1];
    return Math.sqrt(u * u + v * v);
  }

  // Per observation residual lengths: the items' own (maps), or reprojected from the request (tracks).
  function residuals(result, items, req, itemKeyName) {
    const values = [];
    if (items.some((it) => it && Array.isArray(it.residuals))) {
      for (const it of items) for (const r of (it && it.residuals) || []) values.push(Array.isArray(r) ? Math.hypot(...r) : Math.abs(r));
      return {values, unit: "residual length, target units"};
    }
    // a reconstruction's points carry their observations, its cameras the P they were solved in
    if (Array.isArray(result.cameras) && items.some((it) => it && Array.isArray(it.observations))) {
      for (const it of items) {
        if (!it || !Array.isArray(it.point) || !Array.isArray(it.observations)) continue;
        for (const [view, u, v] of it.observations) {
          const camera = result.cameras[view];
          const r = camera && reprojection(camera.P, it.point, [u, v]);
          if (r !== null && r !== undefined) values.push(r);
        }
      }
      return {values, unit: "reprojection error, pixels"};
    }
    const cams = req && req.data && req.data.cameras, inputs = req && req.data && req.data[itemKeyName];
    if (Array.isArray(cams) && Array.isArray(inputs) && items.some((it) => it && Array.isArray(it.point))) {
      items.forEach((it, i) => {
        const input = inputs[i];
        if (!it || !Array.isArray(it.point) || !input || !Array.isArray(input.views)) return;
        for (let j = 0; j < input.views.length; j++) {
          const r = reprojection(cams[input.views[j]], it.point, input.points[j]);
          if (r !== null) values.push(r);
        }
      });
      return {values, unit: "reprojection error, pixels"};
    }
    return null;
  }

  return {scene, residuals};
})();
