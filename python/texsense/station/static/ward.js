// texsense ward overview: one tile per mat, most urgent first. No build step, no dependencies.
// The WebSocket sends only the tiles that changed (docs/station.md, "The ward page's feed"),
// each with its map downsampled to at most 24 x 24 blocks of one byte: mmHg, 0-250.
"use strict";
const token = new URLSearchParams(location.search).get("token");
const withToken = (url) => token ? url + (url.includes("?") ? "&" : "?") + "token=" + encodeURIComponent(token) : url;
const $ = (id) => document.getElementById(id);
const STATE_TEXT = { waiting: "waiting", live: "ok", alert: "reposition!", acknowledged: "acknowledged", stale: "no data", refused: "refused", unwatched: "NOT WATCHED" };
const TOP_MMHG = 100;  // one fixed scale on every tile, 0-100 mmHg (the dashboards' preset)
const NO_READING = 254, NO_ELEMENT = 255;
const mats = new Map();   // id -> the latest tile data
const tiles = new Map();  // id -> its element
let wall = 0;             // the station's clock at the latest message
let member = null;        // this station's name in its group (none: not in a group)
function drawMini(canvas, map) {
  const ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  if (!map) return;
  const bytes = Uint8Array.from(atob(map.b64), (ch) => ch.charCodeAt(0));
  const s = Math.min(canvas.width / map.cols, canvas.height / map.rows);
  const ox = (canvas.width - s * map.cols) / 2, oy = (canvas.height - s * map.rows) / 2;
  // one colour is one pressure on every mat of the ward (each byte: the block's peak, mmHg)
  bytes.forEach((v, k) => {
    if (v === NO_ELEMENT) return;
    const r = Math.floor(k / map.cols), c = k % map.cols;
    ctx.fillStyle = v === NO_READING ? "#d1d5db" : colourOf("viridis", v / TOP_MMHG);
    ctx.fillRect(ox + c * s, oy + r * s, Math.ceil(s), Math.ceil(s));
  });
}
function ago(mat) {
  return mat.last_frame_wall === null ? "no frame yet" : `${Math.max(0, wall - mat.last_frame_wall).toFixed(1)} s ago`;
}
async function post(url) {
  const r = await fetch(withToken(url), { method: "POST" });
  if (!r.ok) $("counts").textContent = `${url}: ${r.status}`;
}
function tile(mat) {
  const el = document.createElement("div");
  el.className = `tile is-${mat.state}`;  // not the monitor's .alert band style
  el.dataset.id = mat.id;
  el.setAttribute("data-state", mat.state);
  const skipped = mat.malformed + mat.skipped;
  el.innerHTML = `
    <div class="top"><span class="id"></span><span class="state"></span></div>
    <canvas width="160" height="110"></canvas>
    <div class="line"><span>${mat.occupied ? "occupied" : "empty"}</span><span><span class="big">${mat.minutes_since_reposition.toFixed(1)}</span> min</span></div>
    <div class="line bed-line" hidden></div>
    <div class="line problem" hidden></div>
    <div class="line holder" hidden></div>
    <div class="line"><span>${mat.frames} frames · <span class="ago"></span></span><span>${skipped ? skipped + " skipped" : ""}</span></div>`;
  if (mat.bed) {  // a bed: its side and the turning schedule
    const line = el.querySelector(".bed-line");
    const mins = mat.bed.since_turn_s === null ? null : Math.floor(mat.bed.since_turn_s / 60);
    line.hidden = false;
    line.classList.toggle("turn-due", mat.bed.turn_due);
    line.textContent = mat.bed.side === null ? "out of bed"
      : `${mat.bed.side} ${Math.floor(mins / 60)}:${String(mins % 60).padStart(2, "0")} h${mat.bed.turn_due ? " · turn due" : ""}`;
  }
  const trouble = mat.refused || mat.problem;
  if (trouble) {  // a refused mat, a missing or silent device: said on the tile
    const line = el.querySelector(".problem");
    line.hidden = false;
    line.textContent = trouble;
    el.title = trouble;
  }
  if (mat.holder !== undefined) {  // a group: which station watches the mat (docs/station.md)
    const line = el.querySelector(".holder");
    line.hidden = false;
    line.textContent = mat.holder === null ? "no station watches it" : `watched by ${mat.holder}${mat.holder === member ? " (here)" : ""}`;
  }
  el.querySelector(".id").textContent = mat.id;
  el.querySelector(".state").textContent = STATE_TEXT[mat.state] || mat.state;
  el.querySelector(".ago").textContent = ago(mat);
  drawMini(el.querySelector("canvas"), mat.map);
  const button = (text, cls, url) => {
    const b = document.createElement("button");
    b.textContent = text;
    b.className = cls;
    b.onclick = (e) => { e.stopPropagation(); post(url); };
    el.appendChild(b);
  };
  const id = encodeURIComponent(mat.id);
  if (mat.alert && mat.alert.active) button("acknowledge", "ack", `/api/mats/${id}/alerts/${mat.alert.id}/ack`);
  if (mat.refused) button("admit again", "admit", `/api/mats/${id}/admit`);
  const base = mat.holder_url && mat.holder !== member ? mat.holder_url : "";  // its holder's dashboard
  el.onclick = () => { location.href = withToken(`${base}mats/${id}/`); };
  return el;
}
const order = (a, b) => b.urgency - a.urgency || b.minutes_since_reposition - a.minutes_since_reposition || (a.id < b.id ? -1 : a.id > b.id ? 1 : 0);
function render(msg) {
  const h = msg.header;
  wall = msg.wall;
  if (msg.reset) { mats.clear(); tiles.clear(); $("tiles").replaceChildren(); }
  const trouble = h.refusal ? ` · refused: ${h.refusal}` : "";
  member = h.member || null;
  const group = h.group ? ` · group ${h.group}: ${h.member} and ${Object.keys(h.members).filter((m) => m !== h.member && h.members[m].alive).length} other(s)${h.database ? ` · database: ${h.database}` : ""}` : "";
  $("broker").textContent = `${h.broker || "local sources"} · ${h.connected ? "connected" : "disconnected — retrying"}${trouble} · ${h.topic}${group}`;
  for (const mat of msg.mats) {
    mats.set(mat.id, mat);
    const el = tile(mat), old = tiles.get(mat.id);
    if (old) old.replaceWith(el); else $("tiles").appendChild(el);
    tiles.set(mat.id, el);
  }
  for (const [id, el] of tiles) el.querySelector(".ago").textContent = ago(mats.get(id));
  const sorted = [...mats.values()].sort(order).map((m) => tiles.get(m.id));
  const now = [...$("tiles").children];
  if (sorted.some((el, k) => now[k] !== el)) $("tiles").replaceChildren(...sorted);
  const all = [...mats.values()];
  const alerts = all.filter((m) => m.state === "alert").length;
  const stale = all.filter((m) => m.state === "stale" || m.state === "refused" || m.state === "unwatched").length;
  const unknown = h.unknown_topics ? ` · ${h.unknown_topics} unknown topic(s)` : "";
  $("counts").textContent = `${all.length} mats · ${alerts} alert(s) · ${stale} without data${unknown}`;
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
