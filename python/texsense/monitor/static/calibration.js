// texsense: the calibration panel (docs/monitor.md, "Calibrate from the page"): the steps of
// `texsense calibrate wizard` on the live stream, through /api/calibration. Shown by itself
// when the mat has no calibration; otherwise behind the header's "calibrate…" button.
"use strict";
const CAL = {
  state: null, timer: null, map: null, dismissed: false,

  async call(path, method = "GET", body = undefined) {  // the server's reason verbatim on failure
    const r = await fetch(withToken(BASE + path), { method, body: body ? JSON.stringify(body) : undefined,
      headers: body ? { "Content-Type": "application/json" } : {} });
    const d = await r.json().catch(() => ({}));
    if (!r.ok) {
      const detail = typeof d.detail === "string" ? d.detail
        : Array.isArray(d.detail) ? d.detail.map((x) => `${(x.loc || []).slice(1).join(".")}: ${x.msg}`).join("; ") : `HTTP ${r.status}`;
      throw new Error(detail);
    }
    return d;
  },

  message(text, level = "refuse") {
    const m = $("cal-message");
    m.hidden = !text; m.textContent = text || ""; m.dataset.level = level;
  },

  async run(path, body) {  // a step's POST: the state it returns, or its reason shown
    this.message("");
    try { this.show(await this.call(path, "POST", body)); } catch (err) { this.message(err.message); await this.refresh(); }
  },

  async refresh() {
    try { this.show(await this.call("/api/calibration")); } catch (err) { /* the feed line says when the monitor is away */ }
  },

  open() { $("calibration").hidden = false; $("calibrate").classList.add("on"); this.dismissed = false; this.refresh(); },
  close() { $("calibration").hidden = true; $("calibrate").classList.remove("on"); this.dismissed = true; },

  show(s) {
    this.state = s;
    $("calibrate").hidden = !s.available;
    if (!s.available) { $("calibration").hidden = true; return; }
    if (!s.calibrated && !this.dismissed) $("calibration").hidden = false;
    $("calibrate").classList.toggle("on", !$("calibration").hidden);
    const done = new Set(s.done), rec = s.recording, waiting = rec !== null || s.busy !== null;
    const sel = $("cal-material");
    if (!sel.options.length) {
      sel.replaceChildren(...s.presets.map((p) => { const o = document.createElement("option"); o.value = p; o.textContent = p + (p === s.default_material ? " (announced)" : ""); return o; }));
      if (s.default_material) sel.value = s.default_material;
    }
    $("cal-zero").disabled = waiting;
    $("cal-uniform").disabled = waiting || !done.has("zero");
    $("cal-fit").disabled = waiting || !done.has("uniform");
    $("cal-check").disabled = waiting || !done.has("material");
    $("cal-save").disabled = waiting || !done.has("material") || done.has("save");
    for (const step of s.steps) {
      const li = $(`cal-step-${step}`);
      li.classList.toggle("done", done.has(step));
      li.classList.toggle("active", rec !== null ? rec.step === step : s.busy === step);
    }
    $("cal-progress").textContent = rec ? `recording ${rec.step}: ${rec.frames} / ${rec.of} frames…`
      : s.busy ? `${s.busy === "material" ? "fitting" : s.busy === "check" ? "checking" : "saving"}…`
      : s.calibrated ? "the monitor shows calibrated pressure" : "no calibration yet";
    for (const step of ["zero", "uniform"]) {
      const r = s.recordings[step];
      $(`cal-${step}-status`).textContent = r ? `✓ ${r.frames} frames over ${fmt(r.span_s, 1)} s, median ${fmt(r.median_pF, 3)} pF`
        + (r.pressure_ncm2 !== null ? ` at ${fmt(r.pressure_ncm2, 3)} N/cm²` : "") : "";
    }
    this.findings(s);
    this.report(s.check);
    const kind = $("cal-kind");  // the kind of mat: the monitor's mode until a person chooses
    if (!kind.dataset.chosen && view && [...kind.options].some((x) => x.value === view.mode.name)) kind.value = view.mode.name;
    const o = s.orientation || {}, edges = ["top", "bottom", "left", "right"].filter((k) => o[k]);
    $("cal-orient-status").textContent = edges.length ? `now: ${edges.map((k) => `${k} ${o[k]}`).join(", ")}` : "now: unknown (no left or right is named)";
    $("cal-saved").textContent = s.saved ? `✓ in use: ${s.saved.calibration}${s.saved.checked ? "" : " (not checked)"}` : "";
    clearTimeout(this.timer);
    this.timer = waiting ? setTimeout(() => this.refresh(), 300) : null;
  },

  findings(s) {
    const items = [], bar = $("cal-message");
    if (s.refused) items.push(["refuse", !bar.hidden && bar.textContent === s.refused ? "✗ refused: the reasons above" : s.refused]);
    for (const f of s.findings) if (!s.refused || f.level !== "refuse") items.push([f.level, `${f.level === "warn" ? "warning" : "refused"}: ${f.text}`]);
    if (s.fit) items.push(["ok", `✓ fitted ${s.fit.material}: ${s.fit.stages.join(", ")}; gains ${fmt(s.fit.gain[0], 2)}–${fmt(s.fit.gain[1], 2)}`]);
    $("cal-findings").replaceChildren(...items.map(([level, text]) => { const li = document.createElement("li"); li.className = level; li.textContent = text; return li; }));
  },

  report(c) {
    const canvas = $("cal-map");
    canvas.hidden = $("cal-map-legend").hidden = !c;
    if (!c) { $("cal-report").textContent = ""; $("cal-report").classList.remove("fail"); return; }
    if (!this.map) { this.map = new MapView(canvas); this.map.setLayout(status.layout, view ? view.orientation : {}); drawErrorScale($("cal-scale"), c.tolerance); }
    const ctx = canvas.getContext("2d"), off = new Set(c.off.map((o) => o.element));
    ctx.clearRect(0, 0, canvas.width, canvas.height);
    c.error.forEach((e, i) => {
      const [x, y, w, h] = this.map.rects[i];
      if (e === null) { ctx.fillStyle = "#9ca3af"; ctx.fillRect(x, y, w, h); return; }
      ctx.fillStyle = errorColour(e / (2 * c.tolerance));
      ctx.fillRect(x, y, w, h);
      if (off.has(i)) { const lw = w >= 10 ? 1.5 : 1; ctx.strokeStyle = "#111"; ctx.lineWidth = lw; ctx.strokeRect(x + lw / 2, y + lw / 2, w - lw, h - lw); }
    });
    const pct = (e) => `${e > 0 ? "+" : "−"}${fmt(Math.abs(100 * e), 1)} %`;
    const median = c.mat_median_ncm2 === null ? null : c.mat_median_ncm2 / c.pressure_ncm2 - 1;
    $("cal-report").classList.toggle("fail", !c.passed);
    $("cal-report").textContent = `${c.passed ? "✓ passed" : "✗ not passed"}: the mat reads ${fmt(c.mat_median_ncm2, 3)} N/cm² `
      + `for ${fmt(c.pressure_ncm2, 3)} (median, ${median === null ? "–" : pct(median)}); `
      + `${c.off.length} of ${c.working} elements off by more than ${fmt(100 * c.tolerance, 0)} %`
      + (c.failed.length ? `, ${c.failed.length} failed` : "")
      + (c.worst.length ? `. Worst: ${c.worst.map((o) => `${o.name.trim()} ${pct(o.error)}`).join(", ")}` : "");
  },

  wire() {
    $("calibrate").onclick = () => ($("calibration").hidden ? this.open() : this.close());
    $("cal-close").onclick = () => this.close();
    $("cal-reset").onclick = () => this.run("/api/calibration/reset");
    const frames = () => Number($("cal-frames").value) || 10;
    $("cal-zero").onclick = () => this.run("/api/calibration/record/zero", { frames: frames() });
    $("cal-uniform").onclick = () => this.run("/api/calibration/record/uniform", { frames: frames(), pressure: $("cal-pressure").value });
    $("cal-fit").onclick = () => this.run("/api/calibration/fit", { material: $("cal-material").value });
    $("cal-check").onclick = () => this.run("/api/calibration/record/check", { frames: frames(), pressure: $("cal-check-pressure").value });
    $("cal-save").onclick = () => this.run("/api/calibration/save");
    const orient = async (kind) => { await this.run("/api/calibration/orientation", { kind, edge: $("cal-edge").value }); refreshView(); };
    $("cal-orient").onclick = () => orient($("cal-kind").value);
    $("cal-kind").onchange = () => { $("cal-kind").dataset.chosen = "1"; };
    $("cal-orient-none").onclick = () => orient("none");
  },
};

function errorColour(f) {  // relative error -> blue (reads low), white (right), red (reads high)
  const a = Math.min(Math.abs(f), 1), k = Math.round(255 * (1 - a));
  return f < 0 ? `rgb(${k},${Math.round(110 + 145 * (1 - a))},255)` : `rgb(255,${k},${k})`;
}
function drawErrorScale(canvas, tol) {
  const ctx = canvas.getContext("2d");
  for (let x = 0; x < canvas.width; x++) { ctx.fillStyle = errorColour((2 * x / (canvas.width - 1) - 1)); ctx.fillRect(x, 0, 1, canvas.height); }
  canvas.title = `relative error, −${2 * 100 * tol} % … +${2 * 100 * tol} %`;
}

CAL.wire();
(async function waitForStatus() {  // the map needs the layout (live.js fetches it)
  if (typeof status === "undefined" || status === null) { setTimeout(waitForStatus, 200); return; }
  await CAL.refresh();
  setInterval(() => { if (!$("calibration").hidden && !CAL.timer) CAL.refresh(); }, 3000);
})();
