// A small line plot on a canvas: axes with ticks, then curves. No library, no network.
"use strict";

const LabrigPlot = (() => {
  function niceTicks(lo, hi, count) {
    if (!(hi > lo)) { hi = lo + 1; }
    const raw = (hi - lo) / count;
    const mag = Math.pow(10, Math.floor(Math.log10(raw)));
    const step = [1, 2, 5, 10].map((m) => m * mag).find((s) => s >= raw) || raw;
    const ticks = [];
    for (let t = Math.ceil(lo / step) * step; t <= hi + 1e-9 * step; t += step) { ticks.push(t); }
    return ticks;
  }

  function range(arrays) {
    let lo = Infinity, hi = -Infinity;
    for (const a of arrays) {
      if (!a) { continue; }
      for (const v of a) { if (v !== null && isFinite(v)) { if (v < lo) lo = v; if (v > hi) hi = v; } }
    }
    if (!isFinite(lo)) { return [0, 1]; }
    if (hi === lo) { return [lo - 1, hi + 1]; }
    const pad = 0.04 * (hi - lo);
    return [lo - pad, hi + pad];
  }

  // curves: [{x: [...], y: [...], color: "#...", dash: [..] }]; returns the points drawn
  function draw(canvas, curves, labels) {
    const ctx = canvas.getContext("2d");
    const w = canvas.width, h = canvas.height;
    const m = { l: 58, r: 12, t: 10, b: 36 };
    ctx.clearRect(0, 0, w, h);
    ctx.fillStyle = "#fff";
    ctx.fillRect(0, 0, w, h);
    const [x0, x1] = range(curves.map((c) => c.x));
    const [y0, y1] = range(curves.map((c) => c.y));
    const sx = (x) => m.l + (x - x0) / (x1 - x0) * (w - m.l - m.r);
    const sy = (y) => h - m.b - (y - y0) / (y1 - y0) * (h - m.t - m.b);
    ctx.strokeStyle = "#999";
    ctx.fillStyle = "#333";
    ctx.font = "11px sans-serif";
    ctx.lineWidth = 1;
    ctx.beginPath();
    ctx.moveTo(m.l, m.t); ctx.lineTo(m.l, h - m.b); ctx.lineTo(w - m.r, h - m.b);
    ctx.stroke();
    ctx.textAlign = "center";
    for (const t of niceTicks(x0, x1, 6)) {
      ctx.fillText(+t.toPrecision(6) + "", sx(t), h - m.b + 14);
    }
    ctx.textAlign = "right";
    for (const t of niceTicks(y0, y1, 5)) {
      ctx.fillText(+t.toPrecision(6) + "", m.l - 4, sy(t) + 4);
    }
    ctx.textAlign = "center";
    ctx.fillText(labels.x, (m.l + w - m.r) / 2, h - 4);
    ctx.save();
    ctx.translate(12, (m.t + h - m.b) / 2);
    ctx.rotate(-Math.PI / 2);
    ctx.fillText(labels.y, 0, 0);
    ctx.restore();
    let points = 0;
    for (const c of curves) {
      if (!c.x || !c.y) { continue; }
      ctx.strokeStyle = c.color;
      ctx.lineWidth = c.width || 1.5;
      ctx.setLineDash(c.dash || []);
      ctx.beginPath();
      let pen = false;
      for (let i = 0; i < c.x.length && i < c.y.length; i++) {
        const x = c.x[i], y = c.y[i];
        if (x === null || y === null) { pen = false; continue; }
        if (pen) { ctx.lineTo(sx(x), sy(y)); } else { ctx.moveTo(sx(x), sy(y)); pen = true; }
        points++;
      }
      ctx.stroke();
    }
    ctx.setLineDash([]);
    canvas.dataset.points = String(points);
    return points;
  }

  return { draw };
})();
