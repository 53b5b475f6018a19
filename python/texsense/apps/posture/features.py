"""Features of pressure maps for posture classification (thesis §6.3.2).

The thesis tested every element value, the centre of force, the pressure on 4 and on 16
equal aggregated areas of the seat and (§6.5.2.2) the single-element back sensor, with the
element values normalised to the mean pressure of the mat (§6.4.2), and picked the k best by
sequential forward selection (:func:`texsense.apps.posture.evaluate.sequential_forward_selection`).

Beyond the thesis, for large grids where people lie or sit at different places (PhysioNet
PMD), a map can first be **aligned** (shifted so that its centre of force sits in the middle,
sub-element by linear interpolation), **log-compressed** (``log(1 + p / mean)``: a few
high-pressure bony spots otherwise dominate) and **pooled** (mean of k x k blocks).

A :class:`FeatureSet` is a small, JSON-serialisable definition; a trained
:class:`~texsense.apps.posture.model.PostureModel` stores it next to the layout so the live
monitor computes the same features.

Examples
--------
>>> import numpy as np
>>> from texsense import Layout
>>> from texsense.apps.posture.features import FeatureSet
>>> lay = Layout.grid(4, 4, pitch_cm=2.0)
>>> maps = np.zeros((1, 16)); maps[0, 5] = 2.0           # one loaded element
>>> fs = FeatureSet(("centre", "areas4"))
>>> fs.names(lay)
['cof_x', 'cof_y', 'a1', 'a2', 'a3', 'a4']
>>> fs.transform(maps, lay).round(2).tolist()
[[3.0, 3.0, 4.0, 0.0, 0.0, 0.0]]
"""

from __future__ import annotations

import functools
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense._progress import logger
from texsense.apps.stats import centre_of_force_values
from texsense.data.layout import Layout
from texsense.exceptions import ParameterError

__all__ = [
    "KINDS",
    "FeatureSet",
    "align_maps",
    "area_means",
    "centre_of_force",
    "mirror_frames",
    "mirror_samples",
    "pool_maps",
    "reduce_maps",
]

#: The feature groups a :class:`FeatureSet` can hold.
KINDS = ("elements", "centre", "areas4", "areas16", "back")


def centre_of_force(frames: npt.ArrayLike, layout: Layout) -> np.ndarray:
    """Centre of force (T, 2) in cm (:func:`texsense.apps.stats.centre_of_force_values`), but the
    centre of the sensing area for an unloaded frame, so features stay finite."""
    xy = centre_of_force_values(frames, layout)
    unloaded = np.isnan(xy[:, 0])
    xy[unloaded] = layout.xy_cm.mean(axis=0)
    return xy


def area_means(frames: npt.ArrayLike, layout: Layout, n_areas: int) -> np.ndarray:
    """Mean pressure (T, n_areas) of the elements in each of ``n_areas`` equal rectangles of
    the sensing area (:meth:`Layout.equal_areas`, thesis §6.3.2); 0 for an empty rectangle."""
    v = np.nan_to_num(np.asarray(frames, dtype=np.float64))
    areas = layout.equal_areas(n_areas)
    out = np.zeros((v.shape[0], n_areas))
    for j, idx in enumerate(areas.values()):
        if idx.size:
            out[:, j] = v[:, idx].mean(axis=1)
    return out


def align_maps(maps: npt.ArrayLike, rotate: bool = False) -> np.ndarray:
    """Shift each map (T, rows, cols) so its centre of force lies in the middle of the grid
    (linear interpolation, zeros shifted in); with ``rotate`` also turn it so the principal
    axis of its pressure (the body axis) runs along the rows."""
    from scipy import ndimage  # (a second of import: only where maps are aligned)

    m = np.nan_to_num(np.asarray(maps, dtype=np.float64))
    rows, cols = m.shape[1:]
    r, c = np.mgrid[:rows, :cols]
    out = np.empty_like(m)
    for k, a in enumerate(m):
        force = np.maximum(a, 0.0)  # a compensated reading a little below zero carries no force
        w = force.sum()
        if w <= 0:
            out[k] = a
            continue
        cr, cc = (force * r).sum() / w, (force * c).sum() / w
        shifted = ndimage.shift(a, ((rows - 1) / 2 - cr, (cols - 1) / 2 - cc), order=1)
        if rotate:
            coords = np.vstack([(r - cr).ravel(), (c - cc).ravel()])
            cov = np.cov(coords, aweights=force.ravel())
            axis = np.linalg.eigh(cov)[1][:, 1]  # the longer principal axis (row, col)
            angle = (np.degrees(np.arctan2(axis[1], axis[0])) + 90.0) % 180.0 - 90.0
            shifted = ndimage.rotate(shifted, -angle, reshape=False, order=1)
        out[k] = shifted
    return out


def mirror_frames(frames: npt.ArrayLike, layout: Layout) -> np.ndarray:
    """Frames (T, N) of a grid layout mirrored left to right (the columns reversed).

    A body lying on its right side mirrored is a body lying on its left side: with the labels
    swapped accordingly (:func:`mirror_samples`) this doubles the training data of a classifier
    and teaches it that a bed or seat has no preferred side. Raises ``ParameterError`` when the
    layout is not a grid or its elements are not placed symmetrically (every mirrored element
    must land on an element).
    """
    shape = layout.shape
    if shape is None:
        raise ParameterError("mirroring needs a grid layout")
    v = np.asarray(frames, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != layout.n_elements:
        raise ParameterError(
            f"frames must have shape (T, {layout.n_elements}) for this layout, got {v.shape}"
        )
    occupied = ~np.isnan(layout.to_grid(np.zeros(layout.n_elements)))
    if not np.array_equal(occupied, occupied[:, ::-1]):
        raise ParameterError(
            "the layout's elements are not placed symmetrically left to right; mirroring "
            "would move readings onto empty cells"
        )
    return layout.from_grid(layout.to_grid(v, fill=0.0)[:, :, ::-1])


def mirror_samples(
    frames: npt.ArrayLike,
    labels: npt.ArrayLike,
    layout: Layout,
    mapping: dict[Any, Any],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mirrored copies of the frames whose label has a mirror image in ``mapping``.

    ``mapping`` names, for every label that may be mirrored, the label of its mirror image
    (``{"left": "right", "right": "left", "supine": "supine"}``); frames with other labels
    (an asymmetric posture without a partner) are not copied. Keys are compared as strings,
    so a mapping read back from JSON works for integer labels. Returns the mirrored frames,
    their labels and the indices of the frames they were made from.
    """
    y = np.asarray(labels)
    table = {str(k): v for k, v in mapping.items()}
    index = np.flatnonzero([str(v) in table for v in y])
    if index.size == 0:  # no label of the map: nothing to mirror
        return np.asarray(frames)[:0], y[:0], index
    mirrored = mirror_frames(np.asarray(frames)[index], layout)
    new = np.array([table[str(v)] for v in y[index]], dtype=object)
    return mirrored, new.astype(y.dtype), index


def pool_maps(maps: npt.ArrayLike, k: int) -> np.ndarray:
    """Means of k x k blocks of maps (T, rows, cols). Where k does not divide a side, the
    blocks at that edge are partial and average the cells they hold (the grid is padded with
    missing cells, not trimmed: no element is dropped), and the log says so once per shape."""
    m = np.asarray(maps, dtype=np.float64)
    rows, cols = m.shape[1:]
    pr, pc = (-rows) % k, (-cols) % k
    if pr or pc:
        _say_partial(rows, cols, k, pr, pc)
        m = np.pad(m, ((0, 0), (0, pr), (0, pc)), constant_values=np.nan)
    blocks = m.reshape(-1, (rows + pr) // k, k, (cols + pc) // k, k)
    with np.errstate(invalid="ignore"):
        return np.nanmean(blocks, axis=(2, 4)) if (pr or pc) else blocks.mean(axis=(2, 4))


_SAID: set[tuple[int, int, int]] = set()


def _say_partial(rows: int, cols: int, k: int, pr: int, pc: int) -> None:
    if (rows, cols, k) in _SAID:
        return
    _SAID.add((rows, cols, k))
    parts = []
    if pr:
        parts.append(f"the last row of blocks averages {k - pr} of {k} rows")
    if pc:
        parts.append(f"the last column of blocks averages {k - pc} of {k} columns")
    logger.warning(
        "pool %d on a %d x %d grid: %s (padded with missing cells, nothing dropped)",
        k, rows, cols, " and ".join(parts),
    )  # fmt: skip


def reduce_maps(
    frames: npt.ArrayLike,
    layout: Layout,
    *,
    align: bool = False,
    rotate: bool = False,
    pool: int = 1,
) -> tuple[np.ndarray, Layout]:
    """Frames (T, N) of a grid layout aligned (:func:`align_maps`) and pooled
    (:func:`pool_maps`), with the layout of the pooled grid — e.g. the thesis's 2 x 2
    averaging of its 1024-element reference mat to 256 elements (§6.4.1)."""
    shape = layout.shape
    if shape is None:
        raise ParameterError("align and pool need a grid layout")
    maps = layout.to_grid(np.nan_to_num(np.asarray(frames, dtype=np.float64)), fill=0.0)
    if align:
        maps = align_maps(maps, rotate=rotate)
    if pool == 1:
        return layout.from_grid(maps), layout  # the layout's own elements (empty cells out)
    maps = pool_maps(maps, pool)
    pitch = layout.pitch_cm or (1.0, 1.0)
    small = _pooled_grid(*maps.shape[1:], pitch[0] * pool, pitch[1] * pool)
    return maps.reshape(maps.shape[0], -1), small


@functools.lru_cache(maxsize=32)
def _pooled_grid(rows: int, cols: int, pitch_y: float, pitch_x: float) -> Layout:
    """The layout of a pooled grid, made once (a live monitor pools every frame: building a
    grid's neighbour graph each time cost 13 ms a frame of a 64 x 32 bed)."""
    return Layout.grid(rows, cols, pitch_cm=(pitch_y, pitch_x))


@dataclass(frozen=True)
class FeatureSet:
    """Which features to compute from a pressure map and how.

    Parameters
    ----------
    kinds : tuple of str
        Any of :data:`KINDS`: ``elements`` (every element value), ``centre`` (centre of force
        x, y in cm), ``areas4`` / ``areas16`` (mean pressure of equal areas), ``back`` (the
        back sensor, passed to :meth:`transform`).
    normalise : bool
        Divide element values and area means by the frame's mean pressure (§6.4.2), so the
        body weight drops out.
    align : bool
        Shift every map to centre its centre of force before taking element values (grid
        layouts only).
    rotate : bool
        With ``align``, also turn every map so its principal axis runs along the rows.
    log : bool
        Element values as ``log(1 + value)`` (after normalising).
    pool : int
        Element values as means of ``pool x pool`` blocks (grid layouts only; 1 = off).
    """

    kinds: tuple[str, ...] = ("elements", "centre", "areas4", "areas16")
    normalise: bool = True
    align: bool = False
    rotate: bool = False
    log: bool = False
    pool: int = 1

    def __post_init__(self) -> None:
        kinds = tuple(self.kinds)
        object.__setattr__(self, "kinds", kinds)
        unknown = [k for k in kinds if k not in KINDS]
        if unknown or not kinds:
            raise ParameterError(
                f"feature kinds must be some of {', '.join(KINDS)}; got {list(kinds)}"
            )
        if self.rotate and not self.align:
            raise ParameterError("rotate needs align=True")
        if int(self.pool) != self.pool or self.pool < 1:
            raise ParameterError(f"pool must be an integer >= 1, got {self.pool}")

    # ------------------------------------------------------------------ helpers
    def _check_grid(self, layout: Layout) -> tuple[int, int]:
        shape = layout.shape
        if shape is None:
            raise ParameterError("align and pool need a grid layout")
        return shape

    def _element_values(self, v: np.ndarray, layout: Layout) -> np.ndarray:
        out = v
        if self.align or self.pool > 1:
            out, _ = reduce_maps(v, layout, align=self.align, rotate=self.rotate, pool=self.pool)
        return np.log1p(np.clip(out, 0.0, None)) if self.log else out

    def names(self, layout: Layout) -> list[str]:
        """Feature names, in the column order of :meth:`transform`."""
        names: list[str] = []
        for kind in self.kinds:
            if kind == "elements":
                if self.pool > 1:
                    rows, cols = self._check_grid(layout)
                    k = self.pool  # partial blocks at an edge count (pool_maps)
                    nr, nc = -(-rows // k), -(-cols // k)
                    names += [f"b{r}_{c}" for r in range(nr) for c in range(nc)]
                else:
                    names += [f"e{i + 1}" for i in range(layout.n_elements)]
            elif kind == "centre":
                names += ["cof_x", "cof_y"]
            elif kind in ("areas4", "areas16"):
                n = 4 if kind == "areas4" else 16
                prefix = "a" if n == 4 else "A"
                names += [f"{prefix}{i + 1}" for i in range(n)]
            else:
                names.append("back")
        return names

    def transform(
        self, frames: npt.ArrayLike, layout: Layout, back: npt.ArrayLike | None = None
    ) -> np.ndarray:
        """Features (T, F) of pressure frames (T, N) on ``layout``.

        Parameters
        ----------
        frames : array_like (T, N)
            Pressure (or raw counts); NaN (a missing reading) counts as 0.
        layout : Layout
            Layout of the frames.
        back : array_like (T,), optional
            The back sensor's pressure; required when ``"back"`` is among the kinds.
        """
        v = np.nan_to_num(np.asarray(frames, dtype=np.float64))
        if v.ndim != 2 or v.shape[1] != layout.n_elements:
            raise ParameterError(
                f"frames must have shape (T, {layout.n_elements}) for this layout, got {v.shape}"
            )
        scaled = v
        if self.normalise:
            mean = v.mean(axis=1, keepdims=True)
            scaled = np.divide(v, mean, out=np.zeros_like(v), where=mean > 0)
        parts = []
        for kind in self.kinds:
            if kind == "elements":
                parts.append(self._element_values(scaled, layout))
            elif kind == "centre":
                parts.append(centre_of_force(v, layout))
            elif kind == "areas4":
                parts.append(area_means(scaled, layout, 4))
            elif kind == "areas16":
                parts.append(area_means(scaled, layout, 16))
            else:
                if back is None:
                    raise ParameterError("this feature set uses the back sensor: pass back=")
                b = np.asarray(back, dtype=np.float64).reshape(-1, 1)
                if b.shape[0] != v.shape[0]:
                    raise ParameterError(f"back: expected {v.shape[0]} values, got {b.shape[0]}")
                parts.append(np.nan_to_num(b))
        return np.hstack(parts)

    def describe(self) -> str:
        """In words, e.g. ``elements (centred, log, 2x2 pooled), centre of force, 4 + 16
        areas``."""
        how = [w for w, on in (("centred", self.align), ("rotated", self.rotate),
                               ("log", self.log)) if on]  # fmt: skip
        if self.pool > 1:
            how.append(f"{self.pool}x{self.pool} pooled")
        words = {"elements": "elements" + (f" ({', '.join(how)})" if how else ""),
                 "centre": "centre of force", "back": "back sensor"}  # fmt: skip
        areas = [n for k, n in (("areas4", "4"), ("areas16", "16")) if k in self.kinds]
        out = [words[k] for k in self.kinds if k in words]
        if areas:
            out.append(" + ".join(areas) + " areas")
        return ", ".join(out) + ("" if self.normalise else " (not normalised)")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready definition."""
        d = asdict(self)
        d["kinds"] = list(self.kinds)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FeatureSet:
        """Inverse of :meth:`to_dict` (clear errors for unknown or missing keys)."""
        allowed = {"kinds", "normalise", "align", "rotate", "log", "pool"}
        extra = set(d) - allowed
        if extra:
            raise ParameterError(f"unknown feature-set keys: {', '.join(sorted(extra))}")
        return cls(**{**d, "kinds": tuple(d.get("kinds", ()))})
