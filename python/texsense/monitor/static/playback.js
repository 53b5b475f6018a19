// Playback of the recordings in the monitor's folder: the list, play / pause, scrub, speed,
// jump to events, the frame shown on the map and the charts, the report.
"use strict";

const PB = {
  active: false, name: null, info: null, i: 0, frame: null, playing: false, cache: new Map(),
  onChange: null, loading: false, wanted: null,

  init(onChange) {
    this.onChange = onChange;
    $("pb-play").onclick = () => (this.playing ? this.pause() : this.play());
    $("pb-scrub").addEventListener("input", (e) => { this.pause(); this.seek(Number(e.target.value)); });
    $("pb-speed").onchange = () => { if (this.playing) { this.pause(); this.play(); } };
    $("pb-prev-event").onclick = () => this.jumpEvent(-1);
    $("pb-next-event").onclick = () => this.jumpEvent(1);
    $("pb-live").onclick = () => this.close();
    $("pb-report").onclick = (e) => { e.preventDefault(); this.report(); };
  },

  // The report is made by a POST (it writes a file, so it passes the server's guard for
  // writes), then downloaded from the answer.
  async report() {
    const link = $("pb-report"), name = this.name, label = link.textContent;
    link.textContent = "making the report…";
    try {
      const r = await fetch(this.url("/report?format=pdf"), { method: "POST" });
      if (!r.ok) { const d = await r.json().catch(() => ({})); throw new Error(d.detail || r.status); }
      const url = URL.createObjectURL(await r.blob());
      const a = document.createElement("a");
      a.href = url; a.download = `${name}-report.pdf`; document.body.append(a); a.click(); a.remove();
      setTimeout(() => URL.revokeObjectURL(url), 10000);
      link.textContent = label;
    } catch (err) {
      link.textContent = `report: ${err.message}`;
      setTimeout(() => { link.textContent = label; }, 5000);
    }
  },

  url(path) { return withToken(`${BASE}/api/playback/${encodeURIComponent(this.name)}${path}`); },

  async list() {
    let rows = [];
    try { rows = await api("/api/playback"); } catch (err) { return; }
    $("recordings").replaceChildren(...rows.map((r) => {
      const li = document.createElement("li");
      const name = document.createElement("span"); name.className = "rec-name"; name.textContent = r.name;
      const size = document.createElement("span"); size.className = "small";
      size.textContent = r.recording ? " recording…" : ` ${r.folder ? "folder" : (r.bytes / 1e6).toFixed(1) + " MB"} · ${new Date(r.modified * 1000).toLocaleString()}`;
      const open = document.createElement("button"); open.textContent = "open"; open.className = "rec-open";
      open.dataset.name = r.name; open.disabled = r.recording;
      open.onclick = () => this.open(r.name);
      li.append(open, name, size);
      return li;
    }));
  },

  // a line on the page (never only the console): a recording that does not open, a frame that
  // does not come
  say(text) { $("pb-message").hidden = !text; $("pb-message").textContent = text || ""; },

  async open(name) {
    this.pause();
    const before = $("source").textContent, was = this.name;
    this.name = name; this.cache.clear();
    this.say(`opening ${name}…`);
    let r;
    try { r = await fetch(this.url("")); } catch (err) { r = { ok: false, status: String(err), json: async () => ({}) }; }
    if (!r.ok) {
      const d = await r.json().catch(() => ({}));
      this.say(`${name} does not open: ${d.detail || `HTTP ${r.status}`}`);
      $("source").textContent = before; this.name = this.active ? was : null;
      return;
    }
    this.info = await r.json();
    this.say("");
    this.active = true;
    $("source").textContent = `playing back ${name} · ${this.info.frames} frames`;
    $("playback").hidden = false;
    $("pb-name").textContent = name;
    $("pb-scrub").max = this.info.frames - 1;
    $("pb-frames").textContent = this.info.frames - 1;
    await this.seek(0);
  },

  close() {
    this.pause();
    this.say("");
    this.active = false; this.info = null; this.frame = null; this.name = null;
    $("playback").hidden = true;
    this.onChange("close");
  },

  async fetchFrame(i) {
    if (this.cache.has(i)) return this.cache.get(i);
    const r = await fetch(this.url(`/frames/${i}`));
    if (!r.ok) throw new Error(`frame ${i}: ${r.status}`);
    const f = await r.json();
    if (this.cache.size > 300) this.cache.delete(this.cache.keys().next().value);
    this.cache.set(i, f);
    return f;
  },

  // show frame i (the newest request wins when frames are asked faster than they arrive)
  async seek(i) {
    if (!this.info) return;
    i = Math.max(0, Math.min(this.info.frames - 1, Math.round(i)));
    this.wanted = i;
    if (this.loading) return;
    this.loading = true;
    try {
      while (this.wanted !== null) {
        const k = this.wanted; this.wanted = null;
        const f = await this.fetchFrame(k);
        this.i = k; this.frame = f;
        $("pb-scrub").value = k;
        $("pb-frame").textContent = k;
        $("pb-time").textContent = this.clock(f.t);
        this.onChange("frame");
      }
    } catch (err) {
      this.say(`${this.name}: ${err.message}`);
    } finally { this.loading = false; }
  },

  seekTime(t) { this.seek(this.indexAt(t)); },
  indexAt(t) {  // the last frame at or before t
    const ts = this.info.times; let lo = 0, hi = ts.length - 1;
    while (lo < hi) { const mid = (lo + hi + 1) >> 1; if (ts[mid] <= t) lo = mid; else hi = mid - 1; }
    return lo;
  },
  // the wall-clock time of a time t into the recording (a device at 20x: t / 20 wall seconds)
  clock(t) {
    const i = this.info;
    return i && i.started_at ? new Date((i.started_at + t / (i.clock_rate || 1)) * 1000).toLocaleTimeString() : "+" + clockOf(t);
  },

  play() {
    if (!this.info) return;
    if (this.i >= this.info.frames - 1) this.seek(0);
    this.playing = true; $("pb-play").textContent = "⏸";
    const speed = Number($("pb-speed").value), t0 = this.info.times[this.i], wall0 = performance.now();
    const tick = () => {
      if (!this.playing) return;
      const k = this.indexAt(t0 + (performance.now() - wall0) / 1000 * speed);
      if (k !== this.i) this.seek(k);
      if (k >= this.info.frames - 1) { this.pause(); return; }
      this.timer = setTimeout(tick, 40);
    };
    tick();
  },
  pause() { this.playing = false; clearTimeout(this.timer); $("pb-play").textContent = "▶"; },

  jumpEvent(dir) {
    if (!this.info || !this.info.events.length) return;
    const ev = this.info.events, i = this.i;
    const next = dir > 0 ? ev.find((e) => e.i > i) : [...ev].reverse().find((e) => e.i < i);
    if (next) { this.pause(); this.seek(next.i); }
  },

  // the recording's events in the list, each a button that jumps to its frame
  renderEvents() {
    const head = this.info.started_at ? `recording started ${new Date(this.info.started_at * 1000).toLocaleString()}` : "times since the start";
    $("session-start").textContent = head;
    $("events").replaceChildren(...this.info.events.slice(0, 300).map((e) => {
      const li = document.createElement("li");
      const when = document.createElement("button"); when.className = "when jump"; when.textContent = this.clock(e.t);
      when.title = `frame ${e.i}, ${duration(e.t)} into the recording`;
      when.onclick = () => { this.pause(); this.seek(e.i); };
      const what = document.createElement("span"); what.className = e.kind;
      what.textContent = e.text + (e.source === "recomputed" && this.info.live ? " (recomputed)" : "");
      if (e.wall) when.textContent = new Date(e.wall * 1000).toLocaleTimeString();
      li.classList.toggle("current", e.i === this.i);
      li.append(when, what);
      if (e.places) {  // the grid positions no region names, on a line of their own
        const places = document.createElement("div"); places.className = "places"; places.textContent = e.places;
        what.append(places);
      }
      return li;
    }));
  },
};
