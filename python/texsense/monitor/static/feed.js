// texsense: the state of the monitor's source, in one line under the header: "waiting for the
// first frame from ...", "no frames from serial:/dev/ttyACM0 for 10 s", a device that is
// missing or refuses. Kept apart from the dashboard's drawing (app.js); no dependencies.
"use strict";
(() => {
  const token = new URLSearchParams(location.search).get("token");
  const base = location.pathname.replace(/\/[^/]*$/, "");
  const url = base + "/api/status" + (token ? "?token=" + encodeURIComponent(token) : "");
  const line = document.getElementById("feed-state");
  async function poll() {
    try {
      const r = await fetch(url);
      if (!r.ok) throw new Error(`status ${r.status}`);
      const feed = (await r.json()).feed;
      line.hidden = !feed || feed.state === "live";
      if (feed) { line.textContent = feed.text; line.dataset.state = feed.state; }
    } catch (err) {
      line.hidden = false;
      line.dataset.state = "unreachable";
      line.textContent = `the monitor does not answer (${err.message}); retrying…`;
    }
  }
  poll();
  setInterval(poll, 2000);
})();
