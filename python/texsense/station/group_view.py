"""What a member of a group shows of the mats it does not hold (docs/station.md, "A group of
stations"): a mat held by another member is shown from that member's tiles
(:class:`GroupMatEntry`), one that no alive member holds as *unwatched* (red, on top of the
ward), one whose holder has sent no word for :data:`SILENT_S` as stale; its dashboard is the
holder's (:class:`Elsewhere`: a 307 there, a 503 when nobody holds it)."""

from __future__ import annotations

import json
import time
from typing import TYPE_CHECKING, Any

from texsense.station.ward import URGENCY, MatEntry

if TYPE_CHECKING:
    from texsense.station.group import GroupStation

__all__ = ["SILENT_S", "UNWATCHED", "Elsewhere", "GroupMatEntry"]

#: A mat whose holder has sent no word of it for this long is shown stale, s.
SILENT_S = 5.0
#: The ward page's order for a mat nobody watches: above an alert.
UNWATCHED = 5


class GroupMatEntry(MatEntry):
    """A mat of a group: processed here while held, else shown from its holder's tiles."""

    held = False
    group: GroupStation

    def remote(self) -> tuple[dict[str, Any] | None, str | None, float]:
        """The holder's latest tile of this mat (parsed), its text, and when it came."""
        return self.group.remote_tile(self.id)

    def _away(self) -> tuple[dict[str, Any], str]:
        """The mat as shown when another member holds it, or nobody."""
        tile, text, wall = self.remote()
        holder = self.group.view.holders.get(self.id) if self.group.view else None
        url = self.group.member_url(holder)
        now = time.time()
        if holder is None:
            base = dict(tile or self._blank())
            since = self.group.unwatched_since(self.id)
            problem = f"no station watches this mat (for {now - since:.0f} s)"
            base.update(state="unwatched", urgency=UNWATCHED, holder=None, holder_url=None,
                        problem=problem)  # fmt: skip
            return base, ""
        if tile is None or tile.get("holder") != holder or now - wall > SILENT_S:
            base = dict(tile or self._blank())
            base.update(state="stale", urgency=URGENCY["stale"], holder=holder, holder_url=url,
                        problem=f"no word from {holder} for {now - wall:.0f} s"
                        if tile is not None else f"waiting for word from {holder}")  # fmt: skip
            return base, ""
        return tile, text or ""

    def _blank(self) -> dict[str, Any]:
        return {"id": self.id, "source": self.config.source, "quantity": self.config.quantity,
                "elements": self.config.layout.n_elements, "frames": 0, "messages": 0,
                "malformed": 0, "skipped": 0, "failed": 0, "ignored": 0, "last_error": None,
                "problem": None, "last_frame_wall": None, "period_s": None, "refused": None,
                "occupied": False, "minutes_since_reposition": 0.0, "exposure_s": 0.0,
                "frame_t": None, "alert": None, "bed": None, "map": None}  # fmt: skip

    def view_state(self) -> tuple[str, int]:
        if self.held:
            return super().view_state()
        tile, _ = self._away()
        return str(tile["state"]), int(tile["urgency"])

    def status(self) -> dict[str, Any]:
        if self.held:
            return {**super().status(), "holder": self.group.member, "holder_url": self.group.page}
        tile, _ = self._away()
        return {k: v for k, v in tile.items() if k != "map"}

    def summary(self, now: float) -> dict[str, Any]:
        if self.held:
            return super().summary(now)
        return {**self.status(), "pressure": None, "seconds_since_frame": None}

    def tile(self) -> str:
        if self.held:
            return super().tile()
        tile, text = self._away()
        return text or json.dumps(tile, separators=(",", ":"))

    def check(self, now: float, read_until: float | None = None) -> bool:
        return super().check(now, read_until) if self.held else False


class Elsewhere:
    """ASGI middleware: the dashboard of a mat held by another member is that member's
    (``307`` to the same path there); of a mat nobody watches, ``503`` saying so."""

    def __init__(self, app: Any, station: GroupStation) -> None:
        self.app, self.station = app, station

    async def __call__(self, scope: dict[str, Any], receive: Any, send: Any) -> None:
        path = scope.get("path", "")
        parts = path.split("/")
        mat = parts[2] if scope["type"] in ("http", "websocket") and len(parts) > 2 and \
            parts[1] == "mats" else None  # fmt: skip
        if mat is None or mat not in self.station.mats or mat in self.station.held:
            await self.app(scope, receive, send)
            return
        holder, url = self.station.holder_of(mat)
        why = f"no station watches mat {mat} at the moment"
        if holder == self.station.member:  # its state is being restored here
            holder, url, why = None, None, f"mat {mat} is being taken over here; try again"
        if scope["type"] == "websocket":
            await send({"type": "websocket.close", "code": 4307 if holder else 4503})
            return
        if holder is not None and url is not None:
            query = scope.get("query_string", b"").decode()
            where = url.rstrip("/") + path + (f"?{query}" if query else "")
            status, headers, body = 307, [(b"location", where.encode())], b""
        else:
            status, headers = 503, [(b"content-type", b"text/plain; charset=utf-8")]
            body = why.encode()
        await send({"type": "http.response.start", "status": status, "headers": headers})
        await send({"type": "http.response.body", "body": body})
