// A pressure map on a canvas: one fixed colour scale, the threshold as a contour, the
// orientation at the edges, thin or no cell borders on large mats, failed and repaired
// elements, the centre-of-force trace, a bed's regions, regions of interest; pixels <-> cm.
"use strict";
const MARGIN = 20;  // px round the map for the orientation labels

class MapView {
  constructor(canvas) {
    this.canvas = canvas;
    this.layout = null;
    this.orientation = {};
    this.rects = [];
  }

  // the layout ({shape, cells, pitch_cm, xy_cm}) and orientation ({top, bottom, left, right});
  // the canvas is sized to the mat (cells square, at most data-max-width x data-max-height)
  setLayout(layout, orientation, fixedSize = false) {
    this.layout = layout;
    this.orientation = orientation || {};
    const c = this.canvas, W = Number(c.dataset.maxWidth || c.width), H = Number(c.dataset.maxHeight || c.height);
    if (layout.shape) {
      const [rows, cols] = layout.shape, [py, px] = layout.pitch_cm || [1, 1];
      const s = Math.max(2, Math.floor(Math.min((W - 2 * MARGIN) / cols, (H - 2 * MARGIN) / rows)));
      if (!fixedSize) { c.width = cols * s + 2 * MARGIN; c.height = rows * s + 2 * MARGIN; }
      const ox = (c.width - cols * s) / 2, oy = (c.height - rows * s) / 2;
      this.t = { kx: s / px, ky: s / py, ox, oy, s };
      this.cellIndex = new Int32Array(rows * cols).fill(-1);
      layout.cells.forEach((cell, i) => { this.cellIndex[cell] = i; });
      this.rects = layout.cells.map((cell) => [ox + (cell % cols) * s, oy + Math.floor(cell / cols) * s, s, s]);
    } else {  // discrete sensors: squares at their centres, sized by the nearest neighbour
      const xy = layout.xy_cm, xs = xy.map((p) => p[0]), ys = xy.map((p) => p[1]);
      let d = Infinity;
      for (let i = 0; i < xy.length; i++) for (let j = i + 1; j < Math.min(xy.length, i + 40); j++) d = Math.min(d, Math.hypot(xy[i][0] - xy[j][0], xy[i][1] - xy[j][1]));
      d = Number.isFinite(d) && d > 0 ? d : 1;
      const x0 = Math.min(...xs) - d / 2, x1 = Math.max(...xs) + d / 2, y0 = Math.min(...ys) - d / 2, y1 = Math.max(...ys) + d / 2;
      const k = Math.min((W - 2 * MARGIN) / (x1 - x0), (H - 2 * MARGIN) / (y1 - y0));
      if (!fixedSize) { c.width = Math.ceil((x1 - x0) * k + 2 * MARGIN); c.height = Math.ceil((y1 - y0) * k + 2 * MARGIN); }
      this.t = { kx: k, ky: k, ox: MARGIN - x0 * k, oy: MARGIN - y0 * k, s: d * k };
      this.cellIndex = null;
      this.rects = xy.map(([x, y]) => [this.t.ox + (x - d * 0.45) * k, this.t.oy + (y - d * 0.45) * k, 0.9 * d * k, 0.9 * d * k]);
    }
  }

  toCm(px, py) { return [(px - this.t.ox) / this.t.kx, (py - this.t.oy) / this.t.ky]; }
  elementAt(px, py) {  // the element under a point of the canvas, or -1
    return this.rects.findIndex(([x, y, w, h]) => px >= x && px < x + w && py >= y && py < y + h);
  }
  fromCm(x, y) { return [this.t.ox + x * this.t.kx, this.t.oy + y * this.t.ky]; }
  centre(i) { const r = this.rects[i]; return [r[0] + r[2] / 2, r[1] + r[3] / 2]; }

  // values: one per element in the scale's unit (null: no value); o: {scale: [lo, hi], cmap,
  // threshold, repaired, trace, bedRegions, rois, draft}
  draw(values, o) {
    const ctx = this.canvas.getContext("2d");
    ctx.clearRect(0, 0, this.canvas.width, this.canvas.height);
    if (!this.layout) return;
    const [lo, hi] = o.scale, span = hi - lo || 1;
    const gap = this.t.s >= 12 ? 1 : 0;  // large mats: no borders that hide the body
    values.forEach((v, i) => {
      const [x, y, w, h] = this.rects[i];
      if (v === null || v === undefined) { hatch(ctx, x, y, w, h); return; }
      ctx.fillStyle = colourOf(o.cmap, (v - lo) / span);
      ctx.fillRect(x + gap / 2, y + gap / 2, Math.max(w - gap, 1), Math.max(h - gap, 1));
    });
    if (o.threshold !== null && o.threshold !== undefined) this.contour(ctx, values, o.threshold);
    this.marks(ctx, o);
    this.possible(ctx, o.possible || []);
    if (o.bedRegions) this.bedRegions(ctx, o.bedRegions);
    for (const roi of o.rois || []) this.roi(ctx, roi, false);
    if (o.draft) this.roi(ctx, o.draft, true);
    this.edges(ctx);
  }

  // the threshold as the outline of the region above it (black under white: visible on any
  // colour); an empty cell of a checkerboard counts as above when half or more of its
  // neighbours are, so the outline follows the loaded area, not each cell on its own
  contour(ctx, values, thr) {
    if (!this.cellIndex) return;
    const [rows, cols] = this.layout.shape, s = this.t.s;
    const mask = aboveMask(this.cellIndex, rows, cols, values, thr);
    const on = (r, c) => r >= 0 && c >= 0 && r < rows && c < cols && mask[r * cols + c];
    const path = new Path2D();
    for (let r = 0; r < rows; r++) for (let c = 0; c < cols; c++) {
      if (!mask[r * cols + c]) continue;
      const x = this.t.ox + c * s, y = this.t.oy + r * s;
      if (!on(r - 1, c)) { path.moveTo(x, y); path.lineTo(x + s, y); }
      if (!on(r + 1, c)) { path.moveTo(x, y + s); path.lineTo(x + s, y + s); }
      if (!on(r, c - 1)) { path.moveTo(x, y); path.lineTo(x, y + s); }
      if (!on(r, c + 1)) { path.moveTo(x + s, y); path.lineTo(x + s, y + s); }
    }
    ctx.lineCap = "square";
    ctx.strokeStyle = "#000"; ctx.lineWidth = 3; ctx.stroke(path);
    ctx.strokeStyle = "#fff"; ctx.lineWidth = 1.4; ctx.stroke(path);
  }

  // elements only possibly above the threshold (the upper bound is, the lower is not): dotted
  possible(ctx, elements) {
    ctx.save(); ctx.setLineDash([2, 2]); ctx.strokeStyle = "#b45309"; ctx.lineWidth = 1.5;
    for (const i of elements) { const [x, y, w, h] = this.rects[i]; ctx.strokeRect(x + 1, y + 1, w - 2, h - 2); }
    ctx.restore();
  }

  marks(ctx, o) {
    const small = this.t.s < 14;  // a large mat: rings would hide the map, a dot marks a repair
    ctx.lineWidth = 2; ctx.strokeStyle = "#111"; ctx.fillStyle = "rgba(255,255,255,0.75)";
    for (const i of o.repaired || []) {
      const [x, y] = this.centre(i);
      ctx.beginPath(); ctx.arc(x, y, small ? Math.max(1, 0.12 * this.t.s) : 0.32 * this.t.s, 0, 2 * Math.PI);
      small ? ctx.fill() : ctx.stroke();
    }
    const trace = o.trace || [];
    if (!trace.length || !this.layout.shape) return;
    const px = ([r, c]) => [this.t.ox + (c + 0.5) * this.t.s, this.t.oy + (r + 0.5) * this.t.s];
    ctx.strokeStyle = "rgba(225,29,72,0.7)"; ctx.lineWidth = 2; ctx.beginPath();
    trace.forEach((rc, k) => { const [x, y] = px(rc); k ? ctx.lineTo(x, y) : ctx.moveTo(x, y); });
    ctx.stroke();
    const [x, y] = px(trace[trace.length - 1]);
    ctx.fillStyle = "#fff"; ctx.strokeStyle = "#e11d48"; ctx.lineWidth = 3;
    ctx.beginPath(); ctx.arc(x, y, 6, 0, 2 * Math.PI); ctx.fill(); ctx.stroke();
  }

  // rings over a bed's regions, red when at risk; labels placed so that they do not overlap
  bedRegions(ctx, regions) {
    ctx.font = "11px system-ui, sans-serif";
    const placed = [];
    for (const r of regions) {
      const [x, y] = this.fromCm(r.xy_cm[0], r.xy_cm[1]), rad = 2.2 * this.t.s;
      ctx.lineWidth = 2; ctx.strokeStyle = r.at_risk ? "#dc2626" : "#e5e7eb";
      ctx.beginPath(); ctx.arc(x, y, rad, 0, 2 * Math.PI); ctx.stroke();
      const w = ctx.measureText(r.name).width + 6;
      let lx = x + rad + 3, ly = y - 7;
      if (lx + w > this.canvas.width) lx = x - rad - 3 - w;
      while (placed.some((b) => lx < b[0] + b[2] && b[0] < lx + w && ly < b[1] + 14 && b[1] < ly + 14)) ly += 14;
      placed.push([lx, ly, w]);
      ctx.fillStyle = "rgba(17,24,39,0.7)"; ctx.fillRect(lx, ly, w, 14);
      ctx.fillStyle = r.at_risk ? "#fecaca" : "#fff"; ctx.fillText(r.name, lx + 3, ly + 11);
    }
  }

  roi(ctx, roi, draft) {
    const pts = roi.kind === "box"
      ? [[roi.points[0][0], roi.points[0][1]], [roi.points[1][0], roi.points[0][1]], [roi.points[1][0], roi.points[1][1]], [roi.points[0][0], roi.points[1][1]]]
      : roi.points;
    if (pts.length < 2) return;
    const path = new Path2D();
    pts.forEach(([x, y], k) => { const [px, py] = this.fromCm(x, y); k ? path.lineTo(px, py) : path.moveTo(px, py); });
    if (!draft) path.closePath();
    ctx.setLineDash(draft ? [4, 3] : []);
    ctx.strokeStyle = "#000"; ctx.lineWidth = 3; ctx.stroke(path);
    ctx.strokeStyle = "#f0abfc"; ctx.lineWidth = 1.5; ctx.stroke(path);
    ctx.setLineDash([]);
    if (!draft && roi.name) {
      const [px, py] = this.fromCm(pts[0][0], pts[0][1]);
      ctx.font = "bold 11px system-ui, sans-serif"; ctx.fillStyle = "#000"; ctx.fillText(roi.name, px + 3, py + 12);
      ctx.fillStyle = "#fff"; ctx.fillText(roi.name, px + 2, py + 11);
    }
  }

  // what lies beyond each edge (head/foot, front/back, left/right), in the margins
  edges(ctx) {
    const o = this.orientation, c = this.canvas;
    ctx.font = "11px system-ui, sans-serif"; ctx.fillStyle = "#4b5563"; ctx.textAlign = "center";
    const note = o.assumed ? " (assumed)" : "";
    if (!o.top && !o.bottom && !o.left && !o.right) {  // nobody said how the mat lies
      ctx.font = "italic 11px system-ui, sans-serif"; ctx.fillText("orientation unknown", c.width / 2, 13);
    }
    if (o.top) ctx.fillText(o.top + note, c.width / 2, 13);
    if (o.bottom) ctx.fillText(o.bottom, c.width / 2, c.height - 5);
    for (const [side, x, angle] of [["left", 13, -Math.PI / 2], ["right", c.width - 13, Math.PI / 2]]) {
      if (!o[side]) continue;
      ctx.save(); ctx.translate(x, c.height / 2); ctx.rotate(angle); ctx.fillText(o[side], 0, 4); ctx.restore();
    }
    ctx.textAlign = "start";
  }
}

// cells above the threshold (row-major, rows x cols), an empty cell (no element) counting as
// above when at least half of its elements among the 4 neighbours, and at least two, are
// (as texsense.apps.views.threshold_mask)
function aboveMask(cellIndex, rows, cols, values, thr) {
  const mask = new Uint8Array(rows * cols);
  const above = (k) => cellIndex[k] >= 0 && values[cellIndex[k]] > thr;
  for (let k = 0; k < rows * cols; k++) mask[k] = above(k) ? 1 : 0;
  for (let r = 0; r < rows; r++) for (let c = 0; c < cols; c++) {
    const k = r * cols + c;
    if (cellIndex[k] >= 0) continue;
    let n = 0, up = 0;
    for (const [dr, dc] of [[-1, 0], [1, 0], [0, -1], [0, 1]]) {
      const rr = r + dr, cc = c + dc;
      if (rr < 0 || cc < 0 || rr >= rows || cc >= cols || cellIndex[rr * cols + cc] < 0) continue;
      n++; if (above(rr * cols + cc)) up++;
    }
    mask[k] = up >= 2 && 2 * up >= n ? 1 : 0;
  }
  return mask;
}

function hatch(ctx, x, y, w, h) {  // a failed element without a value
  ctx.fillStyle = "#fff"; ctx.fillRect(x, y, w, h);
  ctx.strokeStyle = "#999"; ctx.lineWidth = 1; ctx.beginPath();
  for (let k = -w; k < w; k += 4) { ctx.moveTo(x + Math.max(k, 0), y + Math.max(-k, 0)); ctx.lineTo(x + Math.min(w, w + k), y + Math.min(h, h - k)); }
  ctx.stroke();
}

// a colour bar from lo to hi with the threshold marked
function drawLegend(canvas, cmap, lo, hi, threshold) {
  const ctx = canvas.getContext("2d"), W = canvas.width, H = canvas.height;
  for (let x = 0; x < W; x++) { ctx.fillStyle = colourOf(cmap, x / (W - 1)); ctx.fillRect(x, 0, 1, H); }
  if (threshold === null || threshold === undefined || !(threshold > lo && threshold < hi)) return;
  const x = Math.round((threshold - lo) / (hi - lo) * (W - 1));
  ctx.fillStyle = "#000"; ctx.fillRect(x - 2, 0, 4, H);
  ctx.fillStyle = "#fff"; ctx.fillRect(x - 1, 0, 2, H);
}
