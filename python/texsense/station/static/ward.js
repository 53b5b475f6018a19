// texsense ward overview: one tile per mat, most urgent first. No build step, no dependencies.
"use strict";
const token = new URLSearchParams(location.search).get("token");
const withToken = (url) => token ? url + (url.includes("?") ? "&" : "?") + "token=" + encodeURIComponent(token) : url;
const $ = (id) => document.getElementById(id);
const TOP_NCM2 = 100 / 75.00615;  // 100 mmHg
const STATE_TEXT = { waiting: "waiting", live: "ok", alert: "reposition!", acknowledged: "acknowledged", stale: "no data", refused: "refused" };
function drawMini(canvas, mat) {
  const ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  if (!mat.shape || !mat.cells || !mat.pressure) return;
  const [rows, cols] = mat.shape;
  const s = Math.min(canvas.width / cols, canvas.height / rows);
  const ox = (canvas.width - s * cols) / 2, oy = (canvas.height - s * rows) / 2;
  // one fixed scale on every tile, 0-100 mmHg (the dashboards' seat and bed preset): one
  // colour is one pressure on every mat of the ward
  mat.cells.forEach((cell, i) => {
    const r = Math.floor(cell / cols), c = cell % cols, v = mat.pressure[i];
    ctx.fillStyle = v === null ? "#d1d5db" : colourOf("viridis", v / TOP_NCM2);
    ctx.fillRect(ox + c * s, oy + r * s, Math.ceil(s), Math.ceil(s));
  });
}
function tile(mat) {
  const el = document.createElement("div");
  el.className = `tile is-${mat.state}`;  // not the monitor's .alert band style
  el.dataset.id = mat.id;
  el.setAttribute("data-state", mat.state);
  const since = mat.seconds_since_frame === null ? "no frame yet" : `${mat.seconds_since_frame.toFixed(1)} s ago`;
  el.innerHTML = `
    <div class="top"><span class="id"></span><span class="state"></span></div>
    <canvas width="160" height="110"></canvas>
    <div class="line"><span>${mat.occupied ? "occupied" : "empty"}</span><span><span class="big">${mat.minutes_since_reposition.toFixed(1)}</span> min</span></div>
    <div class="line bed-line" hidden></div>
    <div class="line"><span>${mat.frames} frames · ${since}</span><span>${mat.malformed ? mat.malformed + " malformed" : ""}</span></div>`;
  if (mat.bed) {  // a bed: its side and the turning schedule
    const line = el.querySelector(".bed-line");
    const mins = mat.bed.since_turn_s === null ? null : Math.floor(mat.bed.since_turn_s / 60);
    line.hidden = false;
    line.classList.toggle("turn-due", mat.bed.turn_due);
    line.textContent = mat.bed.side === null ? "out of bed"
      : `${mat.bed.side} ${Math.floor(mins / 60)}:${String(mins % 60).padStart(2, "0")} h${mat.bed.turn_due ? " · turn due" : ""}`;
  }
  el.querySelector(".id").textContent = mat.id;
  el.querySelector(".state").textContent = STATE_TEXT[mat.state] || mat.state;
  if (mat.refused) el.title = mat.refused;
  drawMini(el.querySelector("canvas"), mat);
  if (mat.alert && mat.alert.active) {
    const b = document.createElement("button");
    b.textContent = "acknowledge";
    b.className = "ack";
    b.onclick = async (e) => {
      e.stopPropagation();
      await fetch(withToken(`/api/mats/${encodeURIComponent(mat.id)}/alerts/${mat.alert.id}/ack`), { method: "POST" });
    };
    el.appendChild(b);
  }
  el.onclick = () => { location.href = withToken(`mats/${encodeURIComponent(mat.id)}/`); };
  return el;
}
function render(ward) {
  $("broker").textContent = `${ward.broker || "local sources"} · ${ward.connected ? "connected" : "disconnected — retrying"} · ${ward.topic}`;
  const alerts = ward.mats.filter((m) => m.state === "alert").length;
  const stale = ward.mats.filter((m) => m.state === "stale" || m.state === "refused").length;
  $("counts").textContent = `${ward.mats.length} mats · ${alerts} alert(s) · ${stale} without data`;
  $("tiles").replaceChildren(...ward.mats.map(tile));
}
function connect() {
  const proto = location.protocol === "https:" ? "wss" : "ws";
  const ws = new WebSocket(withToken(`${proto}://${location.host}/ws/ward`));
  ws.onmessage = (m) => render(JSON.parse(m.data));
  ws.onclose = () => { $("broker").textContent = "station unreachable — retrying…"; setTimeout(connect, 1000); };
}
(function legend() {
  const c = $("ward-scale"), ctx = c.getContext("2d");
  for (let x = 0; x < c.width; x++) { ctx.fillStyle = colourOf("viridis", x / (c.width - 1)); ctx.fillRect(x, 0, 1, c.height); }
})();
connect();
