// Stacked time charts (load, peak, contact area, centre of force; regions of interest) on one
// canvas, with a cursor at the frame shown; a click asks for the frame at that time.
"use strict";

class Charts {
  constructor(canvas, onSeek) {
    this.canvas = canvas;
    this.data = null;
    canvas.addEventListener("click", (e) => {
      if (!this.data || !onSeek) return;
      const box = canvas.getBoundingClientRect(), x = (e.clientX - box.left) * canvas.width / box.width;
      onSeek(this.timeAt(x));
    });
  }

  timeAt(x) { const { t0, t1, left, width } = this.frame; return t0 + (x - left) / width * (t1 - t0); }

  // t: times (s since the start); rows: [{label, lines: [{values, colour}], threshold, band}]
  // (band: {lower, upper} values drawn as a shaded band behind the lines: the peak's bounds);
  // cursor: the time shown (or null); marks: [{t, colour}] (alerts, turns)
  draw(t, rows, cursor, marks) {
    this.data = { t, rows };
    const c = this.canvas, ctx = c.getContext("2d"), W = c.width, H = c.height;
    ctx.clearRect(0, 0, W, H);
    const left = 46, right = 8, top = 4, bottom = 16, gap = 14;
    const h = (H - top - bottom - gap * (rows.length - 1)) / Math.max(rows.length, 1);
    const t0 = t.length ? t[0] : 0, t1 = t.length > 1 ? t[t.length - 1] : t0 + 1;
    this.frame = { t0, t1: t1 > t0 ? t1 : t0 + 1, left, width: W - left - right };
    const X = (v) => left + (v - t0) / (this.frame.t1 - t0) * this.frame.width;
    ctx.font = "10px system-ui, sans-serif";
    rows.forEach((row, k) => {
      const y0 = top + k * (h + gap);
      let lo = Infinity, hi = -Infinity;
      const band = row.band || null, ranged = band ? [...row.lines, { values: band.lower }, { values: band.upper }] : row.lines;
      for (const line of ranged) for (const v of line.values) if (v !== null && Number.isFinite(v)) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
      if (row.threshold !== undefined && row.threshold !== null) hi = Math.max(hi, row.threshold * 1.1);
      if (!Number.isFinite(lo)) { lo = 0; hi = 1; }
      if (row.zero) lo = Math.min(lo, 0);
      if (hi <= lo) hi = lo + 1;
      const Y = (v) => y0 + h - (v - lo) / (hi - lo) * h;
      ctx.fillStyle = "#f8fafc"; ctx.fillRect(left, y0, this.frame.width, h);
      ctx.fillStyle = "#677189"; ctx.textAlign = "right";
      ctx.fillText(fmtShort(hi), left - 4, y0 + 9); ctx.fillText(fmtShort(lo), left - 4, y0 + h);
      ctx.textAlign = "left"; ctx.fillStyle = "#1d2430"; ctx.fillText(row.label, left + 4, y0 + 11);
      for (const m of marks || []) { ctx.fillStyle = m.colour; ctx.fillRect(X(m.t), y0, 1, h); }
      if (row.threshold !== undefined && row.threshold !== null) {
        ctx.strokeStyle = "#c2410c"; ctx.setLineDash([4, 3]); ctx.beginPath();
        ctx.moveTo(left, Y(row.threshold)); ctx.lineTo(W - right, Y(row.threshold)); ctx.stroke(); ctx.setLineDash([]);
      }
      if (band) drawBand(ctx, t, band, X, Y);
      for (const line of row.lines) {
        ctx.strokeStyle = line.colour; ctx.lineWidth = 1.2; ctx.beginPath();
        let pen = false;
        line.values.forEach((v, i) => {
          if (v === null || !Number.isFinite(v)) { pen = false; return; }
          pen ? ctx.lineTo(X(t[i]), Y(v)) : ctx.moveTo(X(t[i]), Y(v)); pen = true;
        });
        ctx.stroke();
      }
    });
    // the time axis: m:ss, or seconds with a decimal for a span under a minute (a short
    // recording otherwise reads 0:00 - 0:00)
    const short = this.frame.t1 - t0 < 60, label = (v) => (short ? `${v.toFixed(1)} s` : clockOf(v));
    this.labels = [label(t0), label(this.frame.t1)];
    ctx.fillStyle = "#677189"; ctx.textAlign = "left"; ctx.fillText(label(t0), left, H - 3);
    ctx.textAlign = "right"; ctx.fillText(label(this.frame.t1), W - right, H - 3); ctx.textAlign = "left";
    if (cursor !== null && cursor !== undefined) { ctx.fillStyle = "#e11d48"; ctx.fillRect(X(cursor) - 1, top, 2, H - top - bottom); }
  }
}

// the band between two series, in runs of frames where both are numbers (a gap ends a run)
function drawBand(ctx, t, band, X, Y) {
  ctx.fillStyle = "rgba(39, 100, 197, 0.18)";
  const ok = (i) => band.lower[i] !== null && band.upper[i] !== null && Number.isFinite(band.lower[i]) && Number.isFinite(band.upper[i]);
  let i = 0;
  while (i < t.length) {
    if (!ok(i)) { i++; continue; }
    let j = i;
    while (j + 1 < t.length && ok(j + 1)) j++;
    ctx.beginPath();
    for (let k = i; k <= j; k++) ctx.lineTo(X(t[k]), Y(band.upper[k]));
    for (let k = j; k >= i; k--) ctx.lineTo(X(t[k]), Y(band.lower[k]));
    ctx.closePath(); ctx.fill();
    if (i === j) { ctx.fillRect(X(t[i]) - 1, Y(band.upper[i]), 2, Y(band.lower[i]) - Y(band.upper[i])); }
    i = j + 1;
  }
}

function fmtShort(v) { const a = Math.abs(v); return a >= 100 ? v.toFixed(0) : a >= 10 ? v.toFixed(1) : v.toFixed(2); }
// a time since the start as h:mm:ss or m:ss
function clockOf(s) {
  s = Math.max(0, Math.round(s));
  const h = Math.floor(s / 3600), m = Math.floor(s / 60) % 60, sec = String(s % 60).padStart(2, "0");
  return h ? `${h}:${String(m).padStart(2, "0")}:${sec}` : `${m}:${sec}`;
}
// a duration in words: 8 s, 1 min 15 s, 1 h 30 min (as texsense.apps.views.format_duration)
function duration(s) {
  if (s === null || s === undefined || !Number.isFinite(s)) return "–";
  const sign = s < 0 ? "-" : ""; s = Math.round(Math.abs(s));
  if (s < 60) return `${sign}${s} s`;
  const m = Math.floor(s / 60), r = s % 60;
  if (m < 60) return r ? `${sign}${m} min ${r} s` : `${sign}${m} min`;
  return `${sign}${Math.floor(m / 60)} h ${String(m % 60).padStart(2, "0")} min`;
}
