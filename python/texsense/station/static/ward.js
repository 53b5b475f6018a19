// texsense ward overview: one tile per mat, most urgent first. No build step, no dependencies.
// The WebSocket sends only the tiles that changed (docs/station.md, "The ward page's feed"),
// each with its map downsampled to at most 24 x 24 blocks of one byte: mmHg, 0-250.
"use strict";
const token = new URLSearchParams(location.search).get("token");
const withToken = (url) => token ? url + (url.includes("?") ? "&" : "?") + "token=" + encodeURIComponent(token) : url;
const $ = (id) => document.getElementById(id);
const STATE_TEXT = { waiting: "waiting", live: "ok", alert: "now!", acknowledged: "acknowledged", stale: "no data", refused: "refused", unwatched: "NOT WATCHED" };
const TOP_MMHG = 100;  // one fixed scale on every tile, 0-100 mmHg (the dashboards' preset)
const NO_READING = 254, NO_ELEMENT = 255;
const mats = new Map();   // id -> the latest tile data
const tiles = new Map();  // id -> its element
let wall = 0;             // the station's clock at the latest message
let member = null;        // this station's name in its group (none: not in a group)
// the tile's map, drawn the same way up as the mat's dashboard (row 1 at the top) with what
// lies beyond each edge; whole pixels per block (no seams); a bed drawn as a bed: its
// mattress with the headboard at the head end
function drawMini(canvas, map, mat) {
  const o = mat.orientation || {}, bed = !!mat.bed || mat.mode === "bed", m = 12;  // m: room for the edge labels
  if (map) {  // the canvas takes the mat's shape: a bed is tall, a seat square
    const want = Math.round(Math.min(230, Math.max(100, 150 * map.rows / map.cols + 2 * m)));
    if (canvas.height !== want) canvas.height = want;
  }
  const ctx = canvas.getContext("2d"), W = canvas.width, H = canvas.height;
  ctx.clearRect(0, 0, W, H);
  if (!map) return;
  const bytes = Uint8Array.from(atob(map.b64), (ch) => ch.charCodeAt(0));
  const s = Math.max(1, Math.floor(Math.min((W - 2 * m) / map.cols, (H - 2 * m) / map.rows)));
  const ox = Math.floor((W - s * map.cols) / 2), oy = Math.floor((H - s * map.rows) / 2);
  if (bed) {  // the mattress, and the headboard at the head end (row 1 unless it says otherwise)
    ctx.fillStyle = "#e5e7eb"; ctx.fillRect(ox - 3, oy - 3, s * map.cols + 6, s * map.rows + 6);
    const head = o.bottom === "head" ? oy + s * map.rows + 1 : oy - 6;
    ctx.fillStyle = "#6b7280"; ctx.fillRect(ox - 3, head, s * map.cols + 6, 5);
  }
  // one colour is one pressure on every mat of the ward (each byte: the block's peak, mmHg)
  bytes.forEach((v, k) => {
    if (v === NO_ELEMENT) return;
    const r = Math.floor(k / map.cols), c = k % map.cols;
    ctx.fillStyle = v === NO_READING ? "#d1d5db" : colourOf("viridis", v / TOP_MMHG);
    ctx.fillRect(ox + c * s, oy + r * s, s, s);
  });
  ctx.font = "9px system-ui, sans-serif"; ctx.fillStyle = "#4b5563"; ctx.textAlign = "center";
  if (!o.top && !o.bottom && !o.left && !o.right) { ctx.fillText("orientation unknown", W / 2, 9); return; }
  if (o.top) ctx.fillText(o.top, W / 2, bed ? oy - 8 : 9);
  if (o.bottom) ctx.fillText(o.bottom, W / 2, H - 2);
  for (const [side, x, angle] of [["left", 8, -Math.PI / 2], ["right", W - 8, Math.PI / 2]]) {
    if (!o[side]) continue;
    ctx.save(); ctx.translate(x, H / 2); ctx.rotate(angle); ctx.fillText(o[side], 0, 3); ctx.restore();
  }
}
const hm = (s) => { const m = Math.floor(Math.abs(s) / 60); return `${Math.floor(m / 60)}:${String(m % 60).padStart(2, "0")} h`; };
function ago(mat) {
  return mat.last_frame_wall === null ? "no frame yet" : `${Math.max(0, wall - mat.last_frame_wall).toFixed(1)} s ago`;
}
async function post(url) {
  const r = await fetch(withToken(url), { method: "POST" });
  if (!r.ok) $("counts").textContent = `${url}: ${r.status}`;
}
// A tile is made once per mat and then filled in place: its buttons stay the same elements
// between messages, so a click that lands while the ward updates is never lost (a button
// replaced between mouse-down and mouse-up gets no click) and never hits another mat.
function tile(mat) {
  let el = tiles.get(mat.id);
  if (!el) {
    el = document.createElement("div");
    el.dataset.id = mat.id;
    tiles.set(mat.id, el);
    el.innerHTML = `
    <div class="top"><span class="id"></span><span class="state"></span></div>
    <canvas width="160" height="120"></canvas>
    <div class="line"><span class="occupancy"></span><span class="peak"></span></div>
    <div class="line exposure"><span class="above"></span><span><span class="big"></span> min</span></div>
    <div class="line bed-line" hidden></div>
    <div class="line problem" hidden></div>
    <div class="line holder" hidden></div>
    <div class="line"><span><span class="frames"></span> frames · <span class="ago"></span></span><span class="skipped"></span></div>
    <button class="ack" hidden>acknowledge</button><button class="admit" hidden>admit again</button>`;
    // each button acts on the mat's data at the time of the click
    el.querySelector("button.ack").onclick = (e) => {
      e.stopPropagation();
      const now = mats.get(mat.id);
      if (now.alert) post(`/api/mats/${encodeURIComponent(now.id)}/alerts/${now.alert.id}/ack`);
    };
    el.querySelector("button.admit").onclick = (e) => {
      e.stopPropagation();
      post(`/api/mats/${encodeURIComponent(mat.id)}/admit`);
    };
    el.onclick = () => {
      const now = mats.get(mat.id), id = encodeURIComponent(now.id);
      const base = now.holder_url && now.holder !== member ? now.holder_url : "";  // its holder's dashboard
      location.href = withToken(`${base}mats/${id}/`);
    };
  }
  fill(el, mat);
  return el;
}
function fill(el, mat) {
  el.className = `tile is-${mat.state}${mat.bed || mat.mode === "bed" ? " is-bed" : ""}`;  // not the monitor's .alert band style
  el.setAttribute("data-state", mat.state);
  const skipped = mat.malformed + mat.skipped;
  el.querySelector(".frames").textContent = mat.frames;
  el.querySelector(".skipped").textContent = skipped ? skipped + " skipped" : "";
  el.querySelector(".occupancy").textContent = mat.occupied ? "occupied" : "empty";
  el.querySelector(".peak").textContent = mat.peak_mmhg === null ? "" : `peak ${Math.round(mat.peak_mmhg)} mmHg`;
  el.querySelector(".above").textContent = `above ${mat.threshold_mmhg} mmHg for`;
  el.querySelector(".big").textContent = mat.minutes_since_reposition.toFixed(1);
  const bedLine = el.querySelector(".bed-line");
  bedLine.hidden = !mat.bed;
  if (mat.bed) {  // a bed: its side and the turning schedule, in the dashboard's words
    const b = mat.bed, now = b.turn_due || mat.state === "alert";
    bedLine.classList.toggle("turn-due", now);
    // two parts that never break inside ("turn due in 1:56 h" whole on the next line)
    const parts = b.side === null ? ["out of bed"]
      : [`${b.side} for ${hm(b.since_turn_s)}`, now ? "turn now" : `turn due in ${hm(b.due_in_s)}`];
    bedLine.replaceChildren(...parts.map((text) => Object.assign(document.createElement("span"), { textContent: text })));
  }
  const trouble = mat.refused || mat.problem, problem = el.querySelector(".problem");
  problem.hidden = !trouble;  // a refused mat, a missing or silent device: said on the tile
  problem.textContent = trouble || "";
  el.title = trouble || "";
  const holder = el.querySelector(".holder");
  holder.hidden = mat.holder === undefined;
  if (mat.holder !== undefined) {  // a group: which station watches the mat (docs/station.md)
    holder.textContent = mat.holder === null ? "no station watches it" : `watched by ${mat.holder}${mat.holder === member ? " (here)" : ""}`;
  }
  el.querySelector(".id").textContent = mat.id;
  el.querySelector(".state").textContent = mat.state === "alert" ? `${mat.action} now!` : STATE_TEXT[mat.state] || mat.state;
  el.querySelector(".ago").textContent = ago(mat);
  drawMini(el.querySelector("canvas"), mat.map, mat);
  el.querySelector("button.ack").hidden = !(mat.alert && mat.alert.active);
  el.querySelector("button.admit").hidden = !mat.refused;
}
const order = (a, b) => b.urgency - a.urgency || b.minutes_since_reposition - a.minutes_since_reposition || (a.id < b.id ? -1 : a.id > b.id ? 1 : 0);
// Most urgent first, but tiles never move under a pointer that is aiming: while it moved over
// the tiles in the last HOLD_MS the order waits, then catches up (a parked mouse holds nothing)
const HOLD_MS = 1500;
let aimedAt = -Infinity, pending = null;
for (const kind of ["pointermove", "pointerdown"]) $("tiles").addEventListener(kind, () => { aimedAt = performance.now(); });
function reorder() {
  const wait = aimedAt + HOLD_MS - performance.now();
  if (wait > 0) { if (pending === null) pending = setTimeout(() => { pending = null; reorder(); }, wait); return; }
  const sorted = [...mats.values()].sort(order).map((m) => tiles.get(m.id));
  const now = [...$("tiles").children];
  if (sorted.some((el, k) => now[k] !== el)) $("tiles").replaceChildren(...sorted);
}
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
    const fresh = !tiles.has(mat.id), el = tile(mat);
    if (fresh) $("tiles").appendChild(el);
  }
  for (const [id, el] of tiles) el.querySelector(".ago").textContent = ago(mats.get(id));
  reorder();
  const all = [...mats.values()];
  const alerts = all.filter((m) => m.state === "alert").length;
  const stale = all.filter((m) => m.state === "stale" || m.state === "refused" || m.state === "unwatched").length;
  const unknown = h.unknown_topics ? ` · ${h.unknown_topics} unknown topic(s)` : "";
  // a station that cannot keep up reads the newest frames and skips older ones: said here
  const busy = h.skipped ? ` · ${h.skipped} frames skipped to keep up (${h.behind_s.toFixed(1)} s behind)` : "";
  $("counts").textContent = `${all.length} mats · ${alerts} alert(s) · ${stale} without data${unknown}${busy}`;
}
function connect() {
  const proto = location.protocol === "https:" ? "wss" : "ws";
  const ws = new WebSocket(withToken(`${proto}://${location.host}/ws/ward`));
  ws.onmessage = (m) => render(JSON.parse(m.data));
  ws.onclose = () => { $("broker").textContent = "station unreachable — retrying…"; setTimeout(connect, 1000); };
}
// the tiles the page was served with: drawn at once, before the WebSocket's first message
(function first() {
  const block = $("first-ward"), msg = block && JSON.parse(block.textContent);
  if (msg) render(msg);
})();
(function legend() {
  const c = $("ward-scale"), ctx = c.getContext("2d");
  for (let x = 0; x < c.width; x++) { ctx.fillStyle = colourOf("viridis", x / (c.width - 1)); ctx.fillRect(x, 0, 1, c.height); }
})();
connect();
