"""Splitting a record into monotone branches at the reversals of its input."""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import numpy as np
import numpy.typing as npt

__all__ = ["Branch", "reversal_indices", "split_branches"]


@dataclass(frozen=True)
class Branch:
    """A monotone stretch of a record: samples ``start``..``stop`` (inclusive)."""

    start: int
    stop: int
    rising: bool


def reversal_indices(u: npt.NDArray[np.float64], tolerance: float) -> list[int]:
    """Indices of the input's turning points; a turn counts once the input has moved back by
    more than ``tolerance`` from the running extreme (so noise does not split branches)."""
    turns: list[int] = []
    if u.size < 2:
        return turns
    ext_i = 0
    direction = 0  # +1 rising, -1 falling, 0 undecided
    for k in range(1, u.size):
        if direction >= 0 and u[k] > u[ext_i]:
            ext_i = k
            direction = 1 if u[k] - u[0] > tolerance or direction == 1 else direction
        elif direction <= 0 and u[k] < u[ext_i]:
            ext_i = k
            direction = -1 if u[0] - u[k] > tolerance or direction == -1 else direction
        if direction == 1 and u[ext_i] - u[k] > tolerance:
            turns.append(ext_i)
            direction, ext_i = -1, k
        elif direction == -1 and u[k] - u[ext_i] > tolerance:
            turns.append(ext_i)
            direction, ext_i = 1, k
    return turns


def split_branches(u: npt.ArrayLike, tolerance: float) -> list[Branch]:
    """Monotone branches between turning points (noise below ``tolerance`` ignored)."""
    x = np.asarray(u, dtype=np.float64)
    cuts = [0, *reversal_indices(x, tolerance), x.size - 1]
    out = []
    for a, b in pairwise(cuts):
        if b > a:
            out.append(Branch(a, b, bool(x[b] > x[a])))
    return out
