"""Temporal smoothing of posture predictions for live use: a vote over the last seconds.

A person holds a posture for seconds to minutes, while a classifier decides frame by frame:
single frames flip when a hand moves or an element fails. :class:`WindowVote` keeps the
predictions of the last ``window_s`` seconds and answers the label with the most votes
(weighted by the classifier's confidence where it has one). It only looks back, as a live
monitor must. :func:`window_vote` applies it to a recorded sequence, restarting at every new
sequence (another subject or session), which is how ``texsense posture evaluate --window``
reports the accuracy per window beside the accuracy per frame.

Examples
--------
>>> vote = WindowVote(window_s=5.0)
>>> [vote.step(label, t) for t, label in enumerate(["sit", "sit", "lean", "sit", "lean"])]
['sit', 'sit', 'sit', 'sit', 'sit']
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Hashable
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense.exceptions import ParameterError

__all__ = ["WindowVote", "window_vote"]


class WindowVote:
    """The most voted label of the last ``window_s`` seconds (the present frame included).
    Ties go to the most recent of the tied labels."""

    def __init__(self, window_s: float = 5.0) -> None:
        if not (math.isfinite(window_s) and window_s >= 0):
            raise ParameterError(f"the window must be >= 0 s, got {window_s}")
        self.window_s = float(window_s)
        self._votes: deque[tuple[float, Hashable, float]] = deque()

    def reset(self) -> WindowVote:
        """Forget the votes (a new sequence)."""
        self._votes.clear()
        return self

    def step(self, label: Hashable, t: float, confidence: float = math.nan) -> Any:
        """Add the prediction at time ``t`` (s, not decreasing) and return the window's label
        (time after the value, as the stages' and trackers' ``step``)."""
        if isinstance(t, str) or not isinstance(t, int | float | np.floating | np.integer):
            raise TypeError(f"step(label, t): the time comes second, got {type(t).__name__}")
        if self._votes and t < self._votes[-1][0]:
            raise ParameterError(f"times must not decrease ({t} after {self._votes[-1][0]})")
        weight = confidence if math.isfinite(confidence) and confidence > 0 else 1.0
        self._votes.append((t, label, weight))
        while self._votes[0][0] < t - self.window_s:
            self._votes.popleft()
        score: dict[Hashable, float] = {}
        last: dict[Hashable, int] = {}
        for k, (_, lab, w) in enumerate(self._votes):
            score[lab] = score.get(lab, 0.0) + w
            last[lab] = k
        return max(score, key=lambda lab: (score[lab], last[lab]))

    def state(self) -> dict[str, Any]:
        """The votes of the window, JSON-ready for labels that are (see :meth:`restore`)."""
        return {"window_s": self.window_s, "votes": [list(v) for v in self._votes]}

    def restore(self, state: dict[str, Any]) -> WindowVote:
        """Go on from a :meth:`state` (the window's length stays this vote's own)."""
        try:
            if not isinstance(state["votes"], list):
                raise TypeError("votes that are not a list")
            votes = [(float(t), lab, float(w)) for t, lab, w in state["votes"]]
        except (KeyError, TypeError, ValueError) as e:
            raise ParameterError(f"the stored posture vote lacks or mangles {e}") from None
        times = [t for t, _, _ in votes]
        if not all(math.isfinite(t) and math.isfinite(w) for t, _, w in votes):
            raise ParameterError("the stored posture vote has a time or weight that is not finite")
        if any(not isinstance(lab, str) for _, lab, _ in votes) or times != sorted(times):
            raise ParameterError("the stored posture vote's labels are not text in time order")
        self._votes = deque(votes)
        return self


def window_vote(
    times: npt.ArrayLike,
    labels: npt.ArrayLike,
    window_s: float,
    sequences: npt.ArrayLike | None = None,
    confidence: npt.ArrayLike | None = None,
) -> np.ndarray:
    """:class:`WindowVote` over recorded predictions, restarting where ``sequences`` (one id
    per frame, e.g. subject and session) changes or time runs backwards."""
    t = np.asarray(times, dtype=np.float64)
    y = np.asarray(labels)
    if t.shape != y.shape or t.ndim != 1:
        raise ParameterError(f"times and labels must be (n,), got {t.shape} and {y.shape}")
    seq = np.zeros(t.size, dtype=np.int64) if sequences is None else np.asarray(sequences)
    conf = np.full(t.size, np.nan) if confidence is None else np.asarray(confidence, float)
    vote = WindowVote(window_s)
    out = np.empty_like(y)
    for k in range(t.size):
        if k and (seq[k] != seq[k - 1] or t[k] < t[k - 1]):
            vote.reset()
        out[k] = vote.step(y[k].item() if hasattr(y[k], "item") else y[k], float(t[k]),
                           float(conf[k]))  # fmt: skip
    return out
