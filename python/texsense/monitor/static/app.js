// texsense monitor dashboard: no build step, no dependencies.
"use strict";
const FACTOR = { "N/cm2": 1, "kPa": 10, "mmHg": 75.00615 };
const LABEL = { "N/cm2": "N/cm²", "kPa": "kPa", "mmHg": "mmHg" };
const token = new URLSearchParams(location.search).get("token");
const withToken = (url) => token ? url + (url.includes("?") ? "&" : "?") + "token=" + encodeURIComponent(token) : url;
const $ = (id) => document.getElementById(id);
let layout = null, status = null, last = null, mode = "pressure", unit = "N/cm2";

// perceptual colour map (viridis-like, 6 stops)
const STOPS = [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37], [255, 255, 255]];
function colour(f) {
  if (!Number.isFinite(f)) return "#e5e7eb";
  f = Math.min(Math.max(f, 0), 1) * (STOPS.length - 2);  // compensation noise can dip below 0
  const i = Math.min(Math.floor(f), STOPS.length - 3), t = f - i;
  const c = STOPS[i].map((v, k) => Math.round(v + t * (STOPS[i + 1][k] - v)));
  return `rgb(${c[0]},${c[1]},${c[2]})`;
}
function heat(f) {  // exposure: white -> orange -> dark red
  if (!(f > 0)) return "#f3f4f6";
  f = Math.min(f, 1);
  const r = 255 - Math.round(90 * f), g = Math.round(235 - 200 * f), b = Math.round(200 - 190 * f);
  return `rgb(${r},${g},${b})`;
}
function gridOf(canvas) {
  const [rows, cols] = layout.shape;
  const s = Math.min(canvas.width / cols, canvas.height / rows);
  return { rows, cols, s, ox: (canvas.width - s * cols) / 2, oy: (canvas.height - s * rows) / 2 };
}
function drawMap(canvas, values, fill, marks) {
  const ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  if (!layout || !layout.shape) return;
  const g = gridOf(canvas);
  ctx.fillStyle = "#f8fafc";
  ctx.fillRect(g.ox, g.oy, g.s * g.cols, g.s * g.rows);
  layout.cells.forEach((cell, i) => {
    const r = Math.floor(cell / g.cols), c = cell % g.cols;
    const x = g.ox + c * g.s, y = g.oy + r * g.s;
    const v = values[i];
    if (v === null && marks) {
      ctx.fillStyle = "#fff"; ctx.fillRect(x, y, g.s, g.s);
      ctx.strokeStyle = "#999"; ctx.lineWidth = 1; ctx.beginPath();
      for (let k = -g.s; k < g.s; k += 4) { ctx.moveTo(x + Math.max(k, 0), y + Math.max(-k, 0)); ctx.lineTo(x + Math.min(g.s, g.s + k), y + Math.min(g.s, g.s - k)); }
      ctx.stroke();
    } else {
      ctx.fillStyle = fill(v); ctx.fillRect(x + 0.5, y + 0.5, g.s - 1, g.s - 1);
    }
  });
  if (!marks) return;
  const small = g.s < 10;  // a large mat: rings would hide the map, a dot marks a repair
  ctx.lineWidth = small ? 1 : 2; ctx.strokeStyle = "#111"; ctx.fillStyle = "rgba(17,17,17,0.55)";
  for (const i of marks.repaired) {
    const cell = layout.cells[i], r = Math.floor(cell / g.cols), c = cell % g.cols;
    ctx.beginPath(); ctx.arc(g.ox + (c + 0.5) * g.s, g.oy + (r + 0.5) * g.s, g.s * (small ? 0.18 : 0.32), 0, 2 * Math.PI);
    small ? ctx.fill() : ctx.stroke();
  }
  const trace = marks.trace || [];
  if (trace.length) {
    ctx.strokeStyle = "rgba(225,29,72,0.7)"; ctx.lineWidth = 2; ctx.beginPath();
    trace.forEach(([r, c], k) => { const x = g.ox + (c + 0.5) * g.s, y = g.oy + (r + 0.5) * g.s; k ? ctx.lineTo(x, y) : ctx.moveTo(x, y); });
    ctx.stroke();
    const [r, c] = trace[trace.length - 1];
    ctx.fillStyle = "#fff"; ctx.strokeStyle = "#e11d48"; ctx.lineWidth = 3;
    ctx.beginPath(); ctx.arc(g.ox + (c + 0.5) * g.s, g.oy + (r + 0.5) * g.s, 6, 0, 2 * Math.PI); ctx.fill(); ctx.stroke();
  }
}
function drawScale(canvas, fill) {
  const ctx = canvas.getContext("2d");
  for (let x = 0; x < canvas.width; x++) { ctx.fillStyle = fill(x / (canvas.width - 1)); ctx.fillRect(x, 0, 1, canvas.height); }
}
const fmt = (v, d = 2) => v === null || v === undefined || Number.isNaN(v) ? "–" : Number(v).toFixed(d);

function render() {
  if (!last) return;
  const f = FACTOR[unit];
  let values, top, title, scaleUnit;
  if (mode === "raw") {
    values = last.raw; title = "raw readings"; scaleUnit = last.raw_unit;
    const finite = values.filter((v) => v !== null);
    const lo = Math.min(...finite), hi = Math.max(...finite);
    top = hi - lo || 1;
    values = values.map((v) => v === null ? null : v - lo);
    $("scale-text").textContent = `${fmt(lo)} – ${fmt(hi)} ${scaleUnit}`;
  } else {
    values = last.pressure.map((v) => v === null ? null : v * f);
    // the colour scale reaches at least 3 N/cm² on a seat, 1.5 on a bed (its peaks are lower)
    top = Math.max((status && status.bed ? 1.5 : 3) * f, ...values.filter((v) => v !== null));
    title = "pressure (compensated)";
    $("scale-text").textContent = `0 – ${fmt(top, 1)} ${LABEL[unit]}`;
  }
  $("map-title").textContent = title;
  drawMap($("heatmap"), values, (v) => colour(v / top), { repaired: mode === "raw" ? [] : last.repaired, trace: last.cof_trace });
  if (last.bed) drawRegions($("heatmap"), last.bed.regions);
  const exp = last.exposure_s.map((v) => v === null ? 0 : v);
  const limit = status ? status.reposition_min * 60 : 1200;
  drawMap($("exposure"), exp, (v) => heat(v / limit), null);
  $("exposure-max").textContent = `${fmt(limit / 60, 0)} min`;
  $("frames").textContent = last.frames;
  const st = last.stats;
  $("load").textContent = `${fmt(st.load_N, 0)} N`;
  $("area").textContent = `${fmt(st.contact_area_cm2, 0)} cm²`;
  $("peak").textContent = `${fmt(st.peak_ncm2 * f, unit === "mmHg" ? 0 : 2)} ${LABEL[unit]}`;
  $("ppi").textContent = `${fmt(st.ppi_ncm2 * f, unit === "mmHg" ? 0 : 2)} ${LABEL[unit]}`;
  $("posture").textContent = last.posture ? `${last.posture.label} (${fmt(100 * last.posture.confidence, 0)} %)` : (status && status.posture_model ? "nobody" : "no model");
  $("posture").title = last.posture ? `vote over ${last.posture.window_s} s; this frame alone: ${last.posture.frame_label}` : "";
  $("posture-truth").textContent = last.source.true_posture !== undefined
    ? `simulated person: ${last.source.true_posture === null ? "away" : last.source.true_posture}` : "";
  renderBed(last.bed, f);
  const a = last.alert;
  $("alert").hidden = !a;
  if (a) {
    const mins = fmt(a.peak_exposure_s / 60, 0);
    $("alert").classList.toggle("acked", !a.active);
    $("alert-text").textContent = a.active
      ? `Reposition: pressure above the threshold for ${mins} min on ${a.elements.length} element(s) — time to shift weight or stand up.`
      : `Reposition alert acknowledged (${mins} min); it clears once the skin is offloaded.`;
    $("ack").hidden = !a.active;
    $("ack").dataset.id = a.id;
  }
  $("record").classList.toggle("on", last.recording);
  $("record").textContent = last.recording ? "■ stop recording" : "● record";
  const src = last.source;
  $("source").textContent = `${src.name} · ${src.elements} elements · ${src.errors} malformed input(s) skipped`;
  $("status").textContent = `t = ${fmt(last.t, 1)} s · failed now: ${last.failed.length} (repaired ${last.repaired.length})`;
}

const SIDE_COLOUR = { supine: "#2764c5", prone: "#7c3aed", left: "#059669", right: "#d97706", sitting: "#db2777" };
function drawRegions(canvas, regions) {  // rings over the bony prominences, red when at risk
  const ctx = canvas.getContext("2d"), g = gridOf(canvas), [py, px] = layout.pitch_cm || [1, 1];
  ctx.font = "11px system-ui, sans-serif";
  for (const r of regions) {
    const x = g.ox + (r.xy_cm[0] / px) * g.s, y = g.oy + (r.xy_cm[1] / py) * g.s;
    ctx.lineWidth = 2; ctx.strokeStyle = r.at_risk ? "#dc2626" : "#e5e7eb";
    ctx.beginPath(); ctx.arc(x, y, 2.2 * g.s, 0, 2 * Math.PI); ctx.stroke();
    ctx.fillStyle = "#fff"; ctx.fillText(r.name, x + 2.4 * g.s, y + 4);
  }
}
function renderBed(bed, f) {
  $("bed").hidden = !bed;
  $("turn-alert").hidden = !(bed && bed.turn_due);
  if (!bed) return;
  $("since-turn").textContent = bed.since_turn_s === null ? "out of bed" : `${clock(bed.since_turn_s)} ${bed.side}`;
  const overdue = bed.due_in_s !== null && bed.due_in_s < 0;
  $("due-label").textContent = overdue ? "turn overdue by" : "next turn due in";
  $("due-in").textContent = bed.due_in_s === null ? "–" : clock(Math.abs(bed.due_in_s));
  $("due-in").classList.toggle("overdue", overdue);
  if (bed.turn_due) $("turn-alert-text").textContent = `Turn due: ${clock(bed.since_turn_s)} on ${bed.side} (schedule: every ${clock(bed.interval_s)}).`;
  const total = Object.values(bed.time_per_side_s).reduce((a, b) => a + b, 0) || 1;
  $("sides").replaceChildren(...Object.entries(bed.time_per_side_s).map(([side, s]) => {
    const row = document.createElement("div"); row.className = "side-row";
    const name = document.createElement("span"); name.textContent = side;
    const bar = document.createElement("span"); bar.className = "bar";
    bar.style.width = `${Math.round(140 * s / total)}px`; bar.style.background = SIDE_COLOUR[side] || "#677189";
    const val = document.createElement("span"); val.className = "small"; val.textContent = clock(s);
    row.append(name, bar, val); return row;
  }));
  $("regions").replaceChildren(...bed.regions.map((r) => {
    const li = document.createElement("li"); li.className = r.at_risk ? "risk" : "";
    li.textContent = `${r.name}: ${fmt(r.peak_ncm2 * f, unit === "mmHg" ? 0 : 2)} ${LABEL[unit]}`;
    return li;
  }));
}

// the page's own folder: "" for the monitor at "/", "/mats/<id>" for a mat of a ward station
const BASE = location.pathname.replace(/\/[^/]*$/, "");
async function api(path, method = "GET") {
  const r = await fetch(withToken(BASE + path), { method });
  if (!r.ok) throw new Error(`${method} ${path}: ${r.status}`);
  return r.json();
}
function connect() {
  const proto = location.protocol === "https:" ? "wss" : "ws";
  const ws = new WebSocket(withToken(`${proto}://${location.host}${BASE}/ws`));
  ws.onmessage = (m) => { last = JSON.parse(m.data); requestAnimationFrame(render); };
  ws.onclose = () => { $("source").textContent = "disconnected — retrying…"; setTimeout(connect, 1000); };
}
$("show-pressure").onclick = () => { mode = "pressure"; $("show-pressure").classList.add("on"); $("show-raw").classList.remove("on"); render(); };
$("show-raw").onclick = () => { mode = "raw"; $("show-raw").classList.add("on"); $("show-pressure").classList.remove("on"); render(); };
$("unit").onchange = (e) => { unit = e.target.value; updateThreshold(); render(); };
$("ack").onclick = async (e) => { await api(`/api/alerts/${e.target.dataset.id}/ack`, "POST"); };
$("record").onclick = async () => { await api(last && last.recording ? "/api/record/stop" : "/api/record/start", "POST"); };
function updateThreshold() {
  if (!status) return;
  const t = status.threshold;
  $("threshold").textContent = `${fmt(t.ncm2 * FACTOR[unit], unit === "mmHg" ? 0 : 2)} ${LABEL[unit]} (alert after ${fmt(status.reposition_min, 0)} min)`;
}
const EVENT_TEXT = {
  seated: "load on the mat", left: "mat unloaded", reposition: "reposition alert",
  acknowledged: "alert acknowledged", cleared: "alert cleared (skin offloaded)",
  "in-bed": "in bed", "out-of-bed": "out of bed", turn: "turned", "turn-due": "turn due",
  "turn-done": "turn alert closed",
};
function clock(s) {
  const m = Math.floor(s / 60), h = Math.floor(m / 60);
  return h ? `${h}:${String(m % 60).padStart(2, "0")}:${String(Math.floor(s % 60)).padStart(2, "0")}`
    : `${m}:${String(Math.floor(s % 60)).padStart(2, "0")}`;
}
async function refreshEvents() {
  if (!status) return;
  try {
    const events = await api(`/api/events?session=${status.session}&limit=12`);
    const list = $("events");
    list.replaceChildren(...events.map((e) => {
      const li = document.createElement("li");
      const when = document.createElement("span"); when.className = "when"; when.textContent = clock(e.t);
      const what = document.createElement("span"); what.className = e.kind;
      what.textContent = (EVENT_TEXT[e.kind] || e.kind) + (e.kind === "turn" ? ` ${e.detail.from} → ${e.detail.to}` : "");
      li.append(when, what);
      return li;
    }));
  } catch (err) { /* the next refresh tries again; the connection line shows outages */ }
}
setInterval(refreshEvents, 2000);
drawScale($("scale"), colour);
drawScale($("exposure-scale"), heat);
api("/api/status").then((s) => { status = s; layout = s.layout; updateThreshold(); connect(); refreshEvents(); })
  .catch((e) => { $("source").textContent = String(e); });
