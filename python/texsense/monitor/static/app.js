// texsense monitor dashboard: no build step, no dependencies (docs/monitor.md).
"use strict";
const FACTOR = { "N/cm2": 1, "kPa": 10, "mmHg": 75.00615 };
const LABEL = { "N/cm2": "N/cm²", "kPa": "kPa", "mmHg": "mmHg" };
const token = new URLSearchParams(location.search).get("token");
const withToken = (url) => token ? url + (url.includes("?") ? "&" : "?") + "token=" + encodeURIComponent(token) : url;
const $ = (id) => document.getElementById(id);
// the page's own folder: "" for the monitor at "/", "/mats/<id>" for a mat of a ward station
const BASE = location.pathname.replace(/\/[^/]*$/, "");
const fmt = (v, d = 2) => v === null || v === undefined || Number.isNaN(v) ? "–" : Number(v).toFixed(d);
const saved = {  // what the page remembers (unit, scale, colours), per mode
  get(k, d) { try { const v = localStorage.getItem("texsense." + k); return v === null ? d : JSON.parse(v); } catch (e) { return d; } },
  set(k, v) { try { localStorage.setItem("texsense." + k, JSON.stringify(v)); } catch (e) { /* private mode */ } },
};
let status = null, view = null, last = null, mode = "pressure", unit = "N/cm2", autoTop = 0;
const live = [];  // the live statistics over time (the charts)
const map = new MapView($("heatmap")), exposure = new MapView($("exposure"));
const charts = new Charts($("charts"), (t) => { if (PB.active) { PB.pause(); PB.seekTime(t); } });
const roiChart = new Charts($("roi-chart"), (t) => { if (PB.active) { PB.pause(); PB.seekTime(t); } });

const PRESETS = {  // fixed scales, N/cm²: the seat and bed 0-100 mmHg, the foot 0-600 kPa
  seat: { label: "seat: 0–100 mmHg", range: [0, 100 / 75.00615] },
  bed: { label: "bed: 0–100 mmHg", range: [0, 100 / 75.00615] },
  foot: { label: "foot: 0–600 kPa", range: [0, 60] },
  auto: { label: "fixed at the highest so far", range: null },
  custom: { label: "my range", range: null },
};
const modeName = () => (PB.active ? PB.info.mode.name : view ? view.mode.name : "seat");
const pressureShown = () => (PB.active ? PB.info.quantity === "pressure" : mode !== "raw");
const digits = () => (unit === "mmHg" || unit === "kPa" ? 0 : 2);
// live from a mat with no calibration: raw readings only (no pressure, no pressure unit)
const rawOnly = () => !PB.active && (last ? last.calibrated === false : !!status && status.calibrated === false);
// what the page shows carries no pressure at all: no unit choice, no threshold, no load
const noPressure = () => (PB.active ? PB.info.quantity !== "pressure" : rawOnly());
// live pressure that a calibration computes from capacitance (what the raw toggle contrasts)
const compensates = () => !!status && status.source.quantity === "capacitance" && !rawOnly();
const rawDigits = (v) => { const a = Math.abs(v); return a >= 100 ? 0 : a >= 10 ? 1 : a >= 1 ? 2 : 3; };
// a live frame's raw readings above its lowest one (the map of a mat in its raw unit)
function rawAboveLowest(raw) {
  const finite = raw.filter((v) => v !== null), lo = finite.length ? Math.min(...finite) : 0;
  return { lo, values: raw.map((v) => (v === null ? null : v - lo)) };
}

function fillPresets() {
  const sel = $("scale-preset"), pressure = pressureShown();
  // raw readings: no pressure presets; "this recording" only for a recording played back
  const keys = pressure ? ["seat", "bed", "foot", "auto", "custom"] : PB.active ? ["recording", "auto", "custom"] : ["auto", "custom"];
  sel.replaceChildren(...keys.map((k) => { const o = document.createElement("option"); o.value = k; o.textContent = k === "recording" ? "this recording" : PRESETS[k].label; return o; }));
  const fallback = pressure ? (PRESETS[modeName()] ? modeName() : "auto") : PB.active ? "recording" : "auto";
  const chosen = saved.get(`scale.${modeName()}.${pressure ? "p" : "v"}`, fallback);
  sel.value = keys.includes(chosen) ? chosen : fallback;
}
// the colour scale [lo, hi] in the unit shown: a preset, this recording's, or the user's range
function scale(values) {
  const preset = $("scale-preset").value, f = pressureShown() ? FACTOR[unit] : 1;
  if (preset === "custom") {
    const r = saved.get(`range.${modeName()}.${pressureShown() ? "p" : "v"}`, null);
    if (r && r[1] > r[0]) return [r[0] * f, r[1] * f];
  }
  if (PRESETS[preset] && PRESETS[preset].range) return PRESETS[preset].range.map((v) => v * f);
  if (preset === "recording" && PB.active) return PB.info.scale;
  const top = Math.max(...values.filter((v) => v !== null && Number.isFinite(v)), 0) / f;
  autoTop = Math.max(autoTop, top);  // never shrinks: one colour stays one value
  return [0, (autoTop || 1) * f];
}
function areas() { return PB.active ? PB.info.layout.area_cm2 : view ? view.area_cm2 : null; }

function frameStats(ncm2) {  // load (N), peak, contact area of one frame (N/cm²)
  const a = areas(); let load = 0, peak = -Infinity, area = 0;
  ncm2.forEach((v, i) => { if (v === null) return; peak = Math.max(peak, v); if (v > 0.05) area += a[i]; load += Math.max(v, 0) * a[i]; });
  return { load_N: load, peak_ncm2: Number.isFinite(peak) ? peak : null, contact_area_cm2: area, ppi_ncm2: null };
}

function render() {
  const pb = PB.active && PB.frame;
  // nothing live is drawn while a recording opens (its first frame not yet here): a live
  // render then put the live source back into the header over "playing back ..."
  if ((!pb && !last) || (PB.active && !PB.frame)) return;
  const f = FACTOR[unit], pressure = pressureShown();
  let values, ncm2 = null, thr = null, shownUnit, title, st;
  if (pb) {
    ncm2 = pressure ? PB.frame.values : null;
    values = pressure ? ncm2.map((v) => (v === null ? null : v * f)) : PB.frame.values;
    shownUnit = pressure ? LABEL[unit] : PB.info.unit;
    thr = pressure && PB.info.threshold !== null ? PB.info.threshold * f : null;
    title = `${PB.name} · frame ${PB.i}`;
    st = pressure ? frameStats(ncm2) : null;
  } else if (mode === "raw") {
    const shown = rawAboveLowest(last.raw);
    values = shown.values;
    shownUnit = `${last.raw_unit} above ${fmt(shown.lo, rawDigits(shown.lo))}`; title = "raw readings"; st = last.stats;
  } else {
    ncm2 = last.pressure; values = ncm2.map((v) => (v === null ? null : v * f));
    // "compensated" only where a calibration compensates: a mat that sends pressure is shown as it is
    shownUnit = LABEL[unit]; title = compensates() ? "pressure (compensated)" : "pressure"; st = last.stats;
    thr = view && view.threshold_ncm2 !== null ? view.threshold_ncm2 * f : null;
  }
  // only the controls that apply: the raw/compensated toggle for a calibrated capacitance
  // mat live, the threshold's mark where there is a threshold
  $("data-toggle").hidden = PB.active || !compensates();
  $("threshold-mark").hidden = thr === null;
  const sc = scale(values), vd = pressure ? digits() : rawDigits(sc[1] - sc[0]);
  $("unit-label").hidden = noPressure();  // nothing in a pressure unit to choose
  $("pressure-marks").hidden = noPressure();
  $("map-title").textContent = title;
  map.draw(values, { scale: sc, cmap: $("cmap").value, threshold: thr,
    repaired: pb ? PB.frame.repaired || [] : mode !== "raw" ? last.repaired : [], trace: pb ? [] : last.cof_trace,
    bedRegions: !pb && last.bed ? last.bed.regions : null, rois: ROI.list, draft: ROI.draft,
    possible: !pb && last.possible ? last.possible : [] });
  $("heatmap").dataset.frame = pb ? PB.i : last.frames;
  drawLegend($("scale"), $("cmap").value, sc[0], sc[1], thr);
  $("scale-lo").textContent = fmt(sc[0], vd);
  $("scale-text").textContent = `${fmt(sc[1], vd)} ${shownUnit}`;
  const typing = [$("scale-min"), $("scale-max")].includes(document.activeElement);
  if ($("scale-preset").value !== "custom" && !typing) { $("scale-min").value = fmt(sc[0], vd); $("scale-max").value = fmt(sc[1], vd); }
  $("threshold-note").textContent = thr === null ? "" : `threshold ${fmt(thr, digits())} ${shownUnit}: the outlined cells are above it`;
  ROI.render(PB.active ? PB.info.layout : status.layout, values, areas(), ncm2, shownUnit, vd);
  renderCards(st, f, pb);
  renderCharts(f);
  if (pb) { PB.renderEvents(); $("status").textContent = ""; } else renderLive(f);
}

function renderCards(st, f, pb) {
  const d = digits(), raw = !pb && last.raw_stats ? last.raw_stats : null;
  $("frames").textContent = pb ? `${PB.i} / ${PB.info.frames - 1}` : last.frames;
  $("raw-cards-note").hidden = !raw;
  $("peak-label").textContent = raw ? "peak rise" : "peak";
  $("area-label").textContent = raw ? "elements responding" : "contact area";
  for (const id of ["load", "ppi"]) $(id).title = raw ? "calibrate to see pressure" : "";
  if (raw) {  // no calibration: what the raw readings say, in their unit; no pressure
    $("load").textContent = "–"; $("ppi").textContent = "–";
    $("peak").textContent = raw.peak_rise === null ? "–" : `${fmt(raw.peak_rise, rawDigits(raw.peak_rise))} ${raw.unit}`;
    $("area").textContent = `${raw.responding} of ${raw.working}`;
    $("respond-above").textContent = raw.respond_above === null ? "–" : `${fmt(raw.respond_above, rawDigits(raw.respond_above))} ${raw.unit}`;
    return;
  }
  $("load").textContent = st && st.load_N !== null ? `${fmt(st.load_N, 0)} N` : "–";
  $("area").textContent = st && st.contact_area_cm2 !== null ? `${fmt(st.contact_area_cm2, 0)} cm²` : "–";
  $("peak").textContent = st && st.peak_ncm2 !== null ? `${fmt(st.peak_ncm2 * f, d)} ${LABEL[unit]}` : "–";
  const ppi = pb ? PB.frame.ppi_ncm2 : st ? st.ppi_ncm2 : null;
  $("ppi").textContent = ppi !== null && ppi !== undefined ? `${fmt(ppi * f, d)} ${LABEL[unit]}` : "–";
  if (pb) {  // what the recording says of the frame's posture: the monitor's live vote, a side label
    const p = PB.frame.posture;
    $("posture").textContent = p ? (p.label || "nobody") : "not recorded";
    $("posture-truth").textContent = p ? `from the recording's label ${p.from}` : "";
  }
}

// the peak chart's band: the bounds of the peak (a monitor with bounds, a file with them)
const BAND_NOTE = " · shaded: its bounds";
function renderCharts(f) {
  let t, rows, cursor = null, marks = [];
  if (PB.active) {
    const s = PB.info.series, q = PB.info.quantity === "pressure", k = q ? f : 1;
    t = s.t; cursor = PB.frame ? PB.frame.t : null;
    rows = [];
    if (s.load_N) rows.push({ label: "load N", lines: [{ values: s.load_N, colour: "#2764c5" }], zero: true });
    const scaled = (vs) => vs.map((v) => (v === null ? null : v * k));
    const band = s.peak_lower && s.peak_upper ? { lower: scaled(s.peak_lower), upper: scaled(s.peak_upper) } : null;
    rows.push({ label: `peak ${q ? LABEL[unit] : PB.info.unit}${band ? BAND_NOTE : ""}`, lines: [{ values: scaled(s.peak), colour: "#2764c5" }], band,
      threshold: q && PB.info.threshold !== null ? PB.info.threshold * f : null, zero: true });
    rows.push({ label: "contact area cm²", lines: [{ values: s.area_cm2, colour: "#2764c5" }], zero: true });
    rows.push({ label: "centre of force cm (x, y)", lines: [{ values: s.cof_x, colour: "#0891b2" }, { values: s.cof_y, colour: "#d97706" }] });
    marks = PB.info.events.filter((e) => e.kind === "reposition" || e.kind === "turn-due").map((e) => ({ t: e.t, colour: "#c2410c" }));
    $("chart-note").textContent = "click to go to that time";
  } else if (rawOnly()) {  // no calibration: the raw rise, no pressure
    const u = last && last.raw_stats ? last.raw_stats.unit : status.raw_unit;
    t = live.map((p) => p.t);
    rows = [
      { label: `peak rise ${u}`, lines: [{ values: live.map((p) => p.rise), colour: "#2764c5" }], zero: true },
      { label: "elements responding", lines: [{ values: live.map((p) => p.responding), colour: "#2764c5" }], zero: true },
    ];
    $("chart-note").textContent = `the last ${live.length} frames`;
  } else {
    t = live.map((p) => p.t);
    const scaled = (v) => (v === null ? null : v * f);
    const band = live.some((p) => p.peakHi !== null) ? { lower: live.map((p) => scaled(p.peakLo)), upper: live.map((p) => scaled(p.peakHi)) } : null;
    rows = [
      { label: "load N", lines: [{ values: live.map((p) => p.load), colour: "#2764c5" }], zero: true },
      { label: `peak ${LABEL[unit]}${band ? BAND_NOTE : ""}`, lines: [{ values: live.map((p) => (p.peak === null ? null : p.peak * f)), colour: "#2764c5" }], threshold: view && view.threshold_ncm2 ? view.threshold_ncm2 * f : null, zero: true, band },
      { label: "contact area cm²", lines: [{ values: live.map((p) => p.area), colour: "#2764c5" }], zero: true },
      { label: "centre of force cm (x, y)", lines: [{ values: live.map((p) => p.x), colour: "#0891b2" }, { values: live.map((p) => p.y), colour: "#d97706" }] },
    ];
    $("chart-note").textContent = `the last ${live.length} frames`;
  }
  charts.draw(t, rows, cursor, marks);
  const roiStats = PB.active ? PB.roiStats : null;
  $("roi-chart").hidden = !roiStats || !roiStats.length;
  if (roiStats && roiStats.length) {
    const colours = ["#db2777", "#059669", "#7c3aed", "#d97706", "#0891b2"];
    const k = PB.info.quantity === "pressure" ? f : 1;
    roiChart.draw(PB.info.series.t, [{ label: "regions: peak", zero: true, lines: roiStats.filter((r) => r.peak).map((r, j) => ({ values: r.peak.map((v) => (v === null ? null : v * k)), colour: colours[j % 5] })) }], cursor, []);
  }
}

// the value under the pointer with its bound (issue 37): "83 ± 9 mmHg (95 %)"
function hoverText(i) {
  if (i < 0) return "point at an element for its value and bound";
  const f = FACTOR[unit], d = digits(), pb = PB.active && PB.frame;
  const v = pb ? PB.frame.values[i] : last && last.pressure ? last.pressure[i] : null;
  const lo = pb ? (PB.frame.lower || [])[i] : last && last.lower ? last.lower[i] : undefined;
  const hi = pb ? (PB.frame.upper || [])[i] : last && last.upper ? last.upper[i] : undefined;
  const level = pb ? PB.info.interval : last ? last.interval : null;
  const rep = (pb ? PB.frame.repaired || [] : last ? last.repaired : []).includes(i);
  const name = `element ${i}`;
  if (v === null || v === undefined || !pressureShown()) return `${name}: –`;
  let text = `${name}: ${fmt(v * f, d)} ${LABEL[unit]}`;
  if (lo !== undefined && lo !== null && hi !== undefined && hi !== null) {
    const half = 0.5 * (hi - lo) * f;
    text += Math.abs(v - 0.5 * (lo + hi)) * f < 0.05 * half
      ? ` ± ${fmt(half, d)}` : ` (${fmt(lo * f, d)} … ${fmt(hi * f, d)})`;
    text += ` ${LABEL[unit]} (${fmt(100 * level, 0)} %)`;
  }
  return rep ? `${text}, repaired from its neighbours` : text;
}
$("heatmap").addEventListener("mousemove", (e) => {
  const r = $("heatmap").getBoundingClientRect(), k = $("heatmap").width / r.width;
  $("hover").textContent = hoverText(map.elementAt((e.clientX - r.left) * k, (e.clientY - r.top) * k));
});
$("heatmap").addEventListener("mouseleave", () => { $("hover").textContent = hoverText(-1); });
