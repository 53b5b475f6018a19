// Regions of interest drawn on the map: a box (drag) or a lasso (draw round an area), the
// elements whose centres lie inside (the rule of texsense.apps.roi), their statistics on the frame
// shown, kept by the page and saved with an open recording.
"use strict";

const ROI = {
  tool: null, list: [], draft: null, view: null, onChange: null,

  init(view, onChange) {
    this.view = view; this.onChange = onChange;
    const c = view.canvas;
    const at = (e) => { const b = c.getBoundingClientRect(); return view.toCm((e.clientX - b.left) * c.width / b.width, (e.clientY - b.top) * c.height / b.height); };
    c.addEventListener("pointerdown", (e) => {
      if (!this.tool) return;
      c.setPointerCapture(e.pointerId);
      const p = at(e);
      this.draft = { kind: this.tool, points: this.tool === "box" ? [p, p] : [p] };
    });
    c.addEventListener("pointermove", (e) => {
      if (!this.draft) return;
      const p = at(e);
      if (this.draft.kind === "box") this.draft.points[1] = p;
      else if (this.draft.points.length < 500) this.draft.points.push(p);
      this.onChange(false);
    });
    c.addEventListener("pointerup", () => {
      const d = this.draft; this.draft = null;
      if (!d) return;
      const ok = d.kind === "box" ? Math.abs(d.points[0][0] - d.points[1][0]) > 0 && Math.abs(d.points[0][1] - d.points[1][1]) > 0 : d.points.length >= 3;
      if (ok) {
        let k = this.list.length + 1;
        while (this.list.some((r) => r.name === `region ${k}`)) k++;
        this.list.push({ name: `region ${k}`, kind: d.kind, points: d.points.map(([x, y]) => [Math.round(x * 100) / 100, Math.round(y * 100) / 100]) });
      }
      this.setTool(null);
      this.onChange(true);
    });
    for (const kind of ["box", "lasso"]) $(`roi-${kind}`).onclick = () => this.setTool(this.tool === kind ? null : kind);
    $("roi-clear").onclick = () => { this.list = []; this.onChange(true); };
  },

  setTool(kind) {
    this.tool = kind;
    $("roi-box").classList.toggle("on", kind === "box");
    $("roi-lasso").classList.toggle("on", kind === "lasso");
    this.view.canvas.classList.toggle("drawing", !!kind);
  },

  elements(roi, layout) {
    const out = [], pts = roi.points;
    const xs = pts.map((p) => p[0]), ys = pts.map((p) => p[1]);
    const [x0, x1, y0, y1] = [Math.min(...xs), Math.max(...xs), Math.min(...ys), Math.max(...ys)];
    layout.xy_cm.forEach(([x, y], i) => {
      if (roi.kind === "box") { if (x >= x0 && x <= x1 && y >= y0 && y <= y1) out.push(i); return; }
      let inside = false;  // even-odd rule
      for (let a = 0, b = pts.length - 1; a < pts.length; b = a++) {
        const [xa, ya] = pts[a], [xb, yb] = pts[b];
        if ((ya > y) !== (yb > y) && x < xa + (y - ya) * (xb - xa) / (yb - ya)) inside = !inside;
      }
      if (inside) out.push(i);
    });
    return out;
  },

  // mean and peak in the values' unit, contact area (cm²), load (N: pressure in N/cm² only)
  stats(idx, values, areas, pressureNcm2) {
    let sum = 0, n = 0, peak = -Infinity, area = 0, load = 0;
    for (const i of idx) {
      const v = values[i];
      if (v === null || !Number.isFinite(v)) continue;
      sum += v; n += 1; peak = Math.max(peak, v);
      if (v > 0) area += areas ? areas[i] : 0;
      if (pressureNcm2 && areas) load += Math.max(pressureNcm2[i] || 0, 0) * areas[i];
    }
    return { mean: n ? sum / n : null, peak: n ? peak : null, area, load: pressureNcm2 ? load : null };
  },

  // the table of regions with the frame's numbers; values in the display unit. The rows are
  // rebuilt only when the regions change (a name being typed keeps its focus)
  render(layout, values, areas, pressureNcm2, unitLabel, digits) {
    $("roi-table").hidden = this.list.length === 0;
    const key = JSON.stringify(this.list) + JSON.stringify(layout.shape);
    if (key !== this.renderedKey) {
      this.renderedKey = key;
      this.members = this.list.map((roi) => this.elements(roi, layout));
      $("roi-rows").replaceChildren(...this.list.map((roi, k) => this.row(roi, k)));
    }
    [...$("roi-rows").children].forEach((tr, k) => {
      const idx = this.members[k], st = this.stats(idx, values, areas, pressureNcm2);
      const cells = [idx.length, fmt(st.mean, digits) + " " + unitLabel, fmt(st.peak, digits) + " " + unitLabel,
        fmt(st.area, 0) + " cm²", st.load === null ? "–" : fmt(st.load, 0) + " N"];
      cells.forEach((v, j) => { tr.children[j + 1].textContent = v; });
      tr.dataset.elements = idx.length;
    });
  },

  row(roi, k) {
    const tr = document.createElement("tr");
    const name = document.createElement("input");
    name.value = roi.name; name.size = 10; name.className = "roi-name";
    name.onchange = () => { const v = name.value.trim(); if (v && !this.list.some((r) => r.name === v)) roi.name = v; this.onChange(true); };
    const first = document.createElement("td"); first.append(name);
    const del = document.createElement("button"); del.textContent = "×"; del.title = "remove";
    del.onclick = () => { this.list.splice(k, 1); this.onChange(true); };
    const last = document.createElement("td"); last.append(del);
    tr.append(first, ...[0, 1, 2, 3, 4].map(() => document.createElement("td")), last);
    return tr;
  },
};
