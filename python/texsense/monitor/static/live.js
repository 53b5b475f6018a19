// The live side of the dashboard: alerts in the mode's words, the bed's schedule, exposure,
// events with clock times, the WebSocket, the controls and the start.
"use strict";
const EVENT_TEXT = {  // as texsense.apps.review.EVENT_TEXT
  seated: "sat down", left: "got up", "in-bed": "in bed", "out-of-bed": "out of bed",
  loaded: "load on the mat", unloaded: "mat unloaded", reposition: "reposition alert",
  acknowledged: "alert acknowledged", cleared: "alert cleared (skin offloaded)",
  turn: "turned", "turn-due": "turn due", "turn-done": "turn alert closed",
  calibrated: "calibration in use",
};
const SIDE_COLOUR = { supine: "#2764c5", prone: "#7c3aed", left: "#059669", right: "#d97706", sitting: "#db2777" };

function heat(f) {  // exposure: white -> orange -> dark red
  if (!(f > 0)) return "#f3f4f6";
  f = Math.min(f, 1);
  return `rgb(${255 - Math.round(90 * f)},${Math.round(235 - 200 * f)},${Math.round(200 - 190 * f)})`;
}

function renderLive(f) {
  const exp = last.exposure_s.map((v) => (v === null ? 0 : v));
  const limit = status ? status.reposition_min * 60 : 1200;
  drawExposure(exp, limit);
  $("exposure-max").textContent = duration(limit);
  $("posture").textContent = last.posture ? `${last.posture.label} (${fmt(100 * last.posture.confidence, 0)} %)` : (status && status.posture_model ? "nobody" : "no model");
  // a foot or other mode without a posture model has no posture to show (issue 33: only what applies)
  $("posture").closest(".card").hidden = !PB.active && !last.posture && !(status && status.posture_model) && !!view && !view.mode.alerts;
  $("posture").title = last.posture ? `vote over ${last.posture.window_s} s; this frame alone: ${last.posture.frame_label}` : "";
  $("posture-truth").textContent = last.source.true_posture !== undefined
    ? `simulated person: ${last.source.true_posture === null ? "away" : last.source.true_posture}` : "";
  renderBed(last.bed, f);
  renderAlert(last.alert, f);
  $("in-use").textContent = inUseText(last.in_use);
  $("record").classList.toggle("on", last.recording);
  $("record").textContent = last.recording ? "■ stop recording" : "● record";
  const src = last.source;
  $("source").textContent = `${src.name} · ${src.elements} elements · ${src.errors} malformed input(s) skipped`;
  $("status").textContent = `${duration(last.t - (live.length ? live[0].t0 : last.t))} shown · failed now: ${last.failed.length} (repaired ${last.repaired.length})`;
}

function drawExposure(exp, limit) {  // time above the threshold, white to dark red
  const ctx = exposure.canvas.getContext("2d");
  ctx.clearRect(0, 0, exposure.canvas.width, exposure.canvas.height);
  exp.forEach((v, i) => { const [x, y, w, h] = exposure.rects[i]; ctx.fillStyle = heat(v / limit); ctx.fillRect(x, y, w, h); });
}

// the words of an alert, one vocabulary on every page: "Turn now" (a bed), "Reposition now"
// (a seat), "Offload now"; the places it names are regions only, the rest in its details line
function alertHead(m) { return `${m.action.charAt(0).toUpperCase()}${m.action.slice(1)} now`; }
function alertWhere(a) {
  const w = a.where || [];
  return w.length ? `${w.slice(0, 4).join(", ")}${w.length > 4 ? ` and ${w.length - 4} more` : ""}` : "";
}
// how far above the threshold: one phrase, qualified by the bounds (issue 37): above with the
// bounds' confidence, or only possibly above
function aboveText(a, thr) {
  const pct = last && last.interval ? `${fmt(100 * last.interval, 0)} %` : "";
  if (a.certainty === "confident") return `above ${thr} with ${pct} confidence`;
  if (a.certainty === "possible") return `possibly above ${thr} (not certain at ${pct})`;
  return `above ${thr}`;
}

function renderAlert(a, f) {
  $("alert").hidden = !a;
  if (!a) return;
  const m = view ? view.mode : { action: "reposition", advice: "shift weight or stand up" };
  const thr = view && view.threshold_ncm2 ? `${fmt(view.threshold_ncm2 * f, digits())} ${LABEL[unit]}` : "the threshold";
  const where = alertWhere(a), what = `${where || "pressure"} ${aboveText(a, thr)} for ${duration(a.peak_exposure_s)}`;
  const schedule = last.bed && last.bed.turn_due ? "; the turning schedule's turn is due too" : "";
  $("alert").classList.toggle("acked", !a.active);
  $("alert").classList.toggle("possible", a.certainty === "possible");
  $("alert-text").textContent = a.active
    ? `${alertHead(m)}: ${what} — ${m.advice}${schedule}.`
    : `${alertHead(m).replace(" now", "")} alert acknowledged (${what}); it clears once the skin is offloaded${m.action === "turn" ? " or the patient has turned" : ""}.`;
  const details = a.details || [];
  $("alert-details").hidden = !details.length;
  $("alert-details").textContent = details.length ? `${where ? "also " : "where on the map: "}${details.slice(0, 3).join("; ")}${details.length > 3 ? ` and ${details.length - 3} more places` : ""}` : "";
  $("ack").hidden = !a.active;
  $("ack").dataset.id = a.id;
}

function renderBed(bed, f) {
  $("bed").hidden = !bed;
  if (!bed) { $("turn-alert").hidden = true; return; }
  const pressed = last.alert && last.alert.cleared_t === null;  // an exposure alert asks to turn too
  // the schedule's own band only when the pressure alert is not already asking to turn
  $("turn-alert").hidden = !bed.turn_due || (pressed && last.alert.active);
  $("since-turn").textContent = bed.since_turn_s === null ? "out of bed" : `${duration(bed.since_turn_s)} ${bed.side}`;
  const now = bed.turn_due || pressed;
  $("due-label").textContent = now ? "turn" : "turn due in";
  $("due-in").textContent = now ? "now" : bed.due_in_s === null ? "–" : duration(bed.due_in_s);
  $("due-in").classList.toggle("overdue", now);
  $("due-why").textContent = bed.turn_due ? `schedule: due ${duration(-bed.due_in_s)} ago`
    : pressed ? `pressure alert${alertWhere(last.alert) ? ": " + alertWhere(last.alert) : ""}` : "";
  if (bed.turn_due) $("turn-alert-text").textContent = `Turn now: ${duration(bed.since_turn_s)} on the ${bed.side} side (schedule: every ${duration(bed.interval_s)}).`;
  const total = Object.values(bed.time_per_side_s).reduce((a, b) => a + b, 0) || 1;
  $("sides").replaceChildren(...Object.entries(bed.time_per_side_s).map(([side, s]) => {
    const row = document.createElement("div"); row.className = "side-row";
    const name = document.createElement("span"); name.textContent = side;
    const bar = document.createElement("span"); bar.className = "bar";
    bar.style.width = `${Math.round(140 * s / total)}px`; bar.style.background = SIDE_COLOUR[side] || "#677189";
    const val = document.createElement("span"); val.className = "small"; val.textContent = duration(s);
    row.append(name, bar, val); return row;
  }));
  $("regions").replaceChildren(...bed.regions.map((r) => {
    const li = document.createElement("li"); li.className = r.at_risk ? "risk" : "";
    const bound = r.peak_lo_ncm2 !== undefined ? ` ± ${fmt(0.5 * (r.peak_hi_ncm2 - r.peak_lo_ncm2) * f, digits())}` : "";
    li.textContent = `${r.name}: ${fmt(r.peak_ncm2 * f, digits())}${bound} ${LABEL[unit]}`;
    if (bound && view && view.threshold_ncm2 && r.peak_lo_ncm2 <= view.threshold_ncm2 && r.peak_hi_ncm2 > view.threshold_ncm2) {
      li.className = "possible"; li.textContent += " (possibly above the threshold)";
    }
    return li;
  }));
}

function inUseText(s) {  // the in-use drift correction's state (issue 37)
  if (!s) return "";
  if (s.state === "off") return `drift corrected in use: off (${s.why})`;
  if (s.state !== "correcting") return "drift corrected in use: waiting for a still moment";
  const pct = fmt(100 * s.load_correction, 1);
  return `drift corrected in use: load ${s.load_correction >= 0 ? "+" : ""}${pct} %, since ${duration(s.since_t)} into the data, from ${duration(s.still_s)} still; zero taken ${s.zeroed} ×`
    + (s.weight_n == null ? "" : `; weight ${fmt(s.weight_n, 0)} N, kept ${s.weighed} ×`)
    + `; ${checkedText(s)}`;
}

function checkedText(s) {  // how long ago a still load last agreed with the weight (the bounds widen with it)
  if (s.checked_t == null) {
    return "never checked against a still weight" + (s.checked_age_s == null ? "" : ` (${duration(s.checked_age_s)} since the first correction)`);
  }
  if (s.checked_age_s == null) return `last checked against the weight at ${duration(s.checked_t)} into the data`;
  return `last checked against the weight ${duration(s.checked_age_s)} ago`;
}

async function api(path, method = "GET", body = undefined) {
  const r = await fetch(withToken(BASE + path), { method, body, headers: body ? { "Content-Type": "application/json" } : {} });
  if (!r.ok) { const d = await r.json().catch(() => ({})); throw new Error(`${method} ${path}: ${r.status} ${d.detail || ""}`); }
  return r.json();
}

let sessionStart = null;
async function refreshEvents() {
  if (!status || PB.active) return;
  try {
    if (sessionStart === null) {
      const s = (await api("/api/sessions")).find((x) => x.id === status.session);
      sessionStart = s ? s.started : 0;
      if (s) $("session-start").textContent = `session started ${new Date(s.started * 1000).toLocaleString()}`;
    }
    const events = await api(`/api/events?session=${status.session}&limit=12`);
    $("events").replaceChildren(...events.map((e) => {
      const li = document.createElement("li");
      const when = document.createElement("span"); when.className = "when"; when.textContent = new Date(e.wall * 1000).toLocaleTimeString();
      when.title = `${duration(e.t - (live.length ? live[0].t0 : 0))} into the session`;
      const what = document.createElement("span"); what.className = e.kind;
      let text = EVENT_TEXT[e.kind] || e.kind;
      if (e.kind === "turn") text += ` ${e.detail.from} → ${e.detail.to} after ${duration(e.detail.after_s)}`;
      if (e.kind === "cleared" && e.detail && e.detail.by === "turned") text = "alert cleared (turned)";
      const where = e.detail && Array.isArray(e.detail.where) ? e.detail.where : [], more = e.detail && Array.isArray(e.detail.details) ? e.detail.details : [];
      if (where.length) text += `: ${where.slice(0, 4).join(", ")}`;
      else if (more.length) text += `: ${more.slice(0, 2).join("; ")}`;
      what.textContent = text;
      li.append(when, what);
      return li;
    }));
  } catch (err) { /* the next refresh tries again; the connection line shows outages */ }
}

let drawing = false;  // one render per animation frame, however many snapshots came
function onSnapshot(snap) {
  last = snap;
  const uncalibrated = snap.calibrated === false;
  if ($("uncalibrated").hidden === uncalibrated) applyCalibrated(!uncalibrated, snap.raw_unit);
  const st = snap.stats, rs = snap.raw_stats, t0 = live.length ? live[0].t0 : snap.t;
  live.push({ t: snap.t - t0, t0, load: st.load_N, peak: st.peak_ncm2, area: st.contact_area_cm2, x: st.cof_cm ? st.cof_cm[0] : null, y: st.cof_cm ? st.cof_cm[1] : null,
    rise: rs ? rs.peak_rise : null, responding: rs ? rs.responding : null,
    peakLo: st.peak_lower_ncm2 ?? null, peakHi: st.peak_upper_ncm2 ?? null });
  if (live.length > 1200) { const t00 = live[0].t0; live.shift(); live.forEach((p) => { p.t0 = t00; }); }
  if (!PB.active && !drawing) { drawing = true; requestAnimationFrame(() => { drawing = false; render(); }); }
}
// a mat with no calibration shows its raw readings only; a calibration saved on the page turns
// the pressure on (the compensated map, the unit, the pressure presets, the exposure)
function applyCalibrated(calibrated, rawUnit) {
  $("uncalibrated").hidden = calibrated;
  $("raw-unit").textContent = rawUnit || "pF";
  $("show-pressure").disabled = !calibrated;
  if (!calibrated && mode !== "raw") $("show-raw").onclick();
  if (calibrated && mode === "raw") $("show-pressure").onclick();  // calibrated just now (the panel)
  if (!PB.active) $("exposure-panel").hidden = !calibrated || !view.mode.alerts;
}
function connect() {
  const proto = location.protocol === "https:" ? "wss" : "ws";
  const ws = new WebSocket(withToken(`${proto}://${location.host}${BASE}/ws`));
  ws.onmessage = (m) => onSnapshot(JSON.parse(m.data));
  ws.onclose = () => { $("source").textContent = "disconnected — retrying…"; setTimeout(connect, 1000); };
}

// the statistics the monitor holds from before the page was opened: the charts start full
async function loadHistory() {
  try {
    const h = await api("/api/history");
    if (live.length || !h.rows.length) return;
    const t0 = h.rows[0][0];
    for (const [t, load, peak, area, x, y, rise, responding, peakLo, peakHi] of h.rows) {
      live.push({ t: t - t0, t0, load, peak, area, x, y, rise, responding, peakLo: peakLo ?? null, peakHi: peakHi ?? null });
    }
  } catch (err) { /* the charts fill from the live frames */ }
}
// the live mode and orientation again (how the mat lies changed on the calibration panel)
async function refreshView() {
  try { view = await api("/api/view"); if (!PB.active) { layoutMaps(); render(); } } catch (err) { /* next time */ }
}

function layoutMaps() {  // the map of the live mat or of the recording open
  const lay = PB.active ? PB.info.layout : status.layout;
  map.setLayout(lay, PB.active ? PB.info.orientation : view.orientation);
  exposure.setLayout(status.layout, view.orientation, true);
  $("exposure-panel").hidden = !view.mode.alerts || PB.active || rawOnly();
  fillPresets();
  autoTop = 0;
  syncRange();
}

function wire() {
  const show = (m) => {  // the compensated pressure or the raw readings: their own presets
    mode = m; $("show-pressure").classList.toggle("on", m !== "raw"); $("show-raw").classList.toggle("on", m === "raw");
    fillPresets(); autoTop = 0; syncRange(); render();
  };
  $("show-pressure").onclick = () => show("pressure");
  $("show-raw").onclick = () => show("raw");
  $("calibrate-hint").onclick = (e) => { e.preventDefault(); CAL.open(); $("calibration").scrollIntoView(); };
  $("unit").onchange = (e) => { unit = e.target.value; saved.set("unit", unit); updateThreshold(); syncRange(); render(); };
  $("cmap").onchange = (e) => { saved.set("cmap", e.target.value); render(); };
  $("scale-preset").onchange = (e) => { saved.set(`scale.${modeName()}.${pressureShown() ? "p" : "v"}`, e.target.value); autoTop = 0; syncRange(); render(); };
  for (const id of ["scale-min", "scale-max"]) {
    $(id).onchange = () => {
      const f = pressureShown() ? FACTOR[unit] : 1, lo = Number($("scale-min").value), hi = Number($("scale-max").value);
      if (!(hi > lo)) return;
      saved.set(`range.${modeName()}.${pressureShown() ? "p" : "v"}`, [lo / f, hi / f]);
      saved.set(`scale.${modeName()}.${pressureShown() ? "p" : "v"}`, "custom");
      $("scale-preset").value = "custom"; render();
    };
  }
  $("ack").onclick = async (e) => { await api(`/api/alerts/${e.target.dataset.id}/ack`, "POST"); };
  $("record").onclick = async () => { await api(last && last.recording ? "/api/record/stop" : "/api/record/start", "POST"); PB.list(); };
  $("roi-save").onclick = saveRois;
}
function syncRange() {  // the range boxes show the scale in use
  const f = pressureShown() ? FACTOR[unit] : 1;
  let values;
  if (!PB.active && mode === "raw") values = last ? rawAboveLowest(last.raw).values : [];
  else values = ((PB.active && PB.frame ? PB.frame.values : last ? last.pressure : []) || []).map((v) => (v === null ? null : v * f));
  const sc = scale(values), d = pressureShown() ? digits() : rawDigits(sc[1] - sc[0]);
  $("scale-min").value = fmt(sc[0], d); $("scale-max").value = fmt(sc[1], d);
}
function updateThreshold() {
  if (!status) return;
  const t = status.threshold;
  $("threshold").textContent = `${fmt(t.ncm2 * FACTOR[unit], digits())} ${LABEL[unit]} (alert after ${duration(status.reposition_min * 60)})`;
}
async function saveRois() {
  if (!PB.active) return;
  try {
    const r = await api(`/api/playback/${encodeURIComponent(PB.name)}/rois`, "PUT", JSON.stringify(ROI.list));
    PB.roiStats = r.stats;
    $("roi-save").textContent = "saved ✓";
  } catch (err) { $("roi-save").textContent = "not saved"; $("source").textContent = String(err); }
  render();
}

function onPlayback(what) {
  if (what === "close") { ROI.list = saved.get("rois.live", []); PB.roiStats = null; layoutMaps(); refreshEvents(); render(); return; }
  if (what === "frame" && PB.info && !PB.opened) {  // the first frame of a recording just opened
    PB.opened = true; ROI.list = PB.info.rois.slice(); PB.roiStats = null; layoutMaps();
    $("roi-save").textContent = "save with the recording";
    if (ROI.list.length) saveRois();
  }
  render();
}

async function start() {
  wire();
  ROI.init(map, (changed) => {
    if (changed && !PB.active) saved.set("rois.live", ROI.list);
    if (changed && PB.active) $("roi-save").textContent = "save with the recording";
    $("roi-save").hidden = !PB.active;
    render();
  });
  PB.init(onPlayback);
  const open = PB.open.bind(PB);
  PB.open = async (name) => { PB.opened = false; await open(name); $("roi-save").hidden = !PB.active; };
  $("cmap").value = saved.get("cmap", "viridis");
  try {
    [status, view] = await Promise.all([api("/api/status"), api("/api/view")]);
  } catch (e) { $("source").textContent = String(e); return; }
  unit = saved.get("unit", view.mode.unit);
  $("unit").value = unit;
  ROI.list = saved.get("rois.live", []);
  layoutMaps(); syncRange(); updateThreshold();
  await loadHistory();
  connect(); refreshEvents(); PB.list();
  setInterval(refreshEvents, 2000);
  setInterval(() => PB.list(), 10000);
}
start();
