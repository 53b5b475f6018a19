"""Where the elements of a sensor are: :class:`Layout`.

A layout holds, for N elements, their centres and sizes in cm, the 4-neighbour topology used
by the repair of failed elements (thesis eq. 6.14), optional element names and named regions
(for example the thesis's 4 and 16 equal aggregated areas, §6.3.2) and, optionally, an
**orientation**: what lies beyond each edge of the map as it is drawn (row 0 at the top,
column 0 on the left), e.g. ``{"top": "head", "bottom": "foot", "left": "left", "right":
"right"}`` for a bed mat. Viewers and reports label the map's edges with it; a layout without
one (the default, and every layout written before it existed) is drawn without labels.

Coordinates: ``x`` grows along a row (to the right, with the column index), ``y`` grows down
the columns (with the row index), both in cm from the top-left corner of the sensing area.
Elements are numbered 0..N-1; on a grid they are the active cells in row-major order.

Examples
--------
A 3 x 4 grid with 2 cm pitch whose centre cell is empty:

>>> import numpy as np
>>> from texsense import Layout
>>> active = np.ones((3, 4), bool); active[1, 1] = False
>>> lay = Layout.grid(3, 4, pitch_cm=2.0, active=active)
>>> lay.n_elements, lay.shape
(11, (3, 4))
>>> lay.xy_cm[0].tolist()
[1.0, 1.0]

A bed mat whose head end is row 0 (the preset of :data:`ORIENTATIONS`):

>>> bed = Layout.grid(64, 32, pitch_cm=2.54).with_orientation("bed")
>>> bed.orientation["top"], bed.orientation["left"]
('head', 'left')
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense.data import budget
from texsense.data.orientation import (
    EDGES,
    ORIENTATIONS,
    _orientation,
    orientation_toward,
    parse_orientation,
)
from texsense.exceptions import ParameterError

__all__ = [
    "EDGES",
    "ORIENTATIONS",
    "Layout",
    "orientation_toward",
    "parse_orientation",
    "whole_numbers",
]

_FloatArray = npt.NDArray[np.float64]
_IntArray = npt.NDArray[np.int64]


#: Memory per cell while :meth:`Layout.grid` builds a grid (centres, sizes, areas, cells,
#: neighbours and the work arrays), for the memory budget (:mod:`texsense.data.budget`).
BYTES_PER_CELL = 200
#: A grid layout has at most this many cells per element, plus :data:`MAX_EMPTY_CELLS`: every
#: map of it is a dense rows x cols array, so a few elements on a 100000 x 100000 grid would
#: make each map 80 GB.
SPARSE_FACTOR = 64
MAX_EMPTY_CELLS = 1 << 20
#: The largest coordinate, element size and pitch (cm) a layout may hold, and the smallest
#: size: 1 km and 1 nm. A file may declare any finite number; beyond these a mat is no mat,
#: and the arithmetic of its maps and plots overflows (element centres at 1e308 cm were a
#: ``LinAlgError`` or an ``arange`` ``ValueError`` out of ``report``).
MAX_CM = 1e5
MIN_CM = 1e-7


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


class Layout:
    """Positions, sizes, topology and regions of N sensor elements.

    Build layouts with :meth:`grid` (a matrix of elements, some cells possibly empty) or
    :meth:`points` (discrete sensors anywhere); the constructor is the general form used by
    the readers.

    Parameters
    ----------
    xy_cm : array_like, shape (N, 2)
        Element centres in cm (x along a row, y down a column).
    size_cm : array_like, shape (N, 2)
        Element width (x) and height (y) in cm.
    area_cm2 : array_like, shape (N,), optional
        Sensing area of each element in cm²; defaults to width x height.
    shape : (int, int), optional
        Grid shape (rows, cols) if the elements sit on a grid.
    cells : array_like of int, shape (N,), optional
        Flat (row-major) grid cell of each element; required with ``shape``.
    pitch_cm : (float, float), optional
        Grid pitch (row pitch = y, column pitch = x) in cm; grids only.
    neighbours : (indptr, indices), optional
        4-neighbour graph in compressed sparse rows; neighbours of element ``i`` are
        ``indices[indptr[i]:indptr[i + 1]]``. Defaults to no neighbours.
    names : sequence of str, optional
        A name per element (for example the vendor's sensor number).
    regions : mapping of str to array_like of int, optional
        Named groups of element indices.
    orientation : mapping of str to str, or str, optional
        What lies beyond each edge of the map (:data:`EDGES` -> a label such as ``"head"``),
        or a preset name of :data:`ORIENTATIONS`. Default: none declared. It labels the
        drawing only: layouts that differ in nothing else compare equal.
    """

    def __init__(
        self,
        xy_cm: npt.ArrayLike,
        size_cm: npt.ArrayLike,
        *,
        area_cm2: npt.ArrayLike | None = None,
        shape: tuple[int, int] | None = None,
        cells: npt.ArrayLike | None = None,
        pitch_cm: tuple[float, float] | None = None,
        neighbours: tuple[npt.ArrayLike, npt.ArrayLike] | None = None,
        names: Sequence[str] | None = None,
        regions: Mapping[str, npt.ArrayLike] | None = None,
        orientation: Mapping[str, str] | str | None = None,
    ) -> None:
        xy = np.asarray(xy_cm, dtype=np.float64)
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise ParameterError(f"xy_cm: expected shape (N, 2), got {xy.shape}")
        n = xy.shape[0]
        if not np.all(np.abs(xy) <= MAX_CM):  # NaN too
            raise ParameterError(f"xy_cm: element centres must lie within ±{MAX_CM:g} cm")
        size = np.asarray(size_cm, dtype=np.float64)
        if size.shape == (2,):
            size = np.broadcast_to(size, (n, 2))
        if size.shape != (n, 2):
            raise ParameterError(f"size_cm: expected shape ({n}, 2) or (2,), got {size.shape}")
        if not np.all((size >= MIN_CM) & (size <= MAX_CM)):
            raise ParameterError(
                f"size_cm: element sizes must be positive, {MIN_CM:g} to {MAX_CM:g} cm"
            )
        if area_cm2 is None:
            area = size[:, 0] * size[:, 1]
        else:
            area = np.broadcast_to(np.asarray(area_cm2, dtype=np.float64), (n,))
            if not np.all((area >= MIN_CM**2) & (area <= MAX_CM**2)):
                raise ParameterError(
                    f"area_cm2: element areas must be positive, {MIN_CM**2:g} to {MAX_CM**2:g} cm2"
                )
        self._xy = _readonly(xy)
        self._size = _readonly(size)
        self._area = _readonly(area)

        self._shape, self._cells, self._pitch = _grid_of(n, shape, cells, pitch_cm)
        indptr, indices = _neighbours_of(n, neighbours)
        self._indptr = _readonly(indptr)
        self._indices = _readonly(indices)

        if names is not None:
            names = [str(s) for s in names]
            if len(names) != n:
                raise ParameterError(f"names: expected {n} names, got {len(names)}")
        self._names: tuple[str, ...] | None = None if names is None else tuple(names)

        self._regions: dict[str, _IntArray] = {}
        if not isinstance(regions or {}, Mapping):  # a list or text from a file's layout
            raise ParameterError(f"regions: expected names and their elements, got {regions!r:.40}")
        for name, members in (regions or {}).items():
            m = whole_numbers(members, f"region {name!r}").ravel()
            if m.size and (m.min() < 0 or m.max() >= n):
                raise ParameterError(f"region {name!r}: element indices must lie in 0..{n - 1}")
            self._regions[str(name)] = _readonly(m)
        self._orientation = _orientation(orientation)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def grid(
        cls,
        rows: int,
        cols: int,
        *,
        pitch_cm: float | tuple[float, float] = 1.0,
        active: npt.ArrayLike | None = None,
        element_size_cm: float | tuple[float, float] | None = None,
        neighbour_gap: int = 1,
        regions: Mapping[str, npt.ArrayLike] | None = None,
    ) -> Layout:
        """A rows x cols matrix of elements, some cells possibly empty.

        Parameters
        ----------
        rows, cols : int
            Grid shape.
        pitch_cm : float or (float, float)
            Centre-to-centre distance in cm; a pair is (row pitch = y, column pitch = x).
        active : array_like of bool, shape (rows, cols), optional
            True where a cell holds an element (for example a checkerboard, or Tekscan's
            non-'B' cells). Default: every cell.
        element_size_cm : float or (float, float), optional
            Element (height, width) in cm; default the pitch (no gaps).
        neighbour_gap : int
            How many empty cells may lie between two elements that are still 4-neighbours.
            The default 1 links the elements of a checkerboard (thesis §6.2.1) but not
            elements separated by a wider gap (Tekscan's 2-cell 'B' stripes between pads).
        regions : mapping, optional
            Named element groups.
        """
        rows, cols = int(rows), int(cols)
        if rows < 1 or cols < 1:
            raise ParameterError(f"grid: rows and cols must be >= 1, got {rows} x {cols}")
        budget.check(rows * cols * BYTES_PER_CELL, f"a grid of {rows} x {cols} elements")
        pitch = np.broadcast_to(np.asarray(pitch_cm, dtype=np.float64), (2,))
        py, px = float(pitch[0]), float(pitch[1])
        if not (py > 0 and px > 0):
            raise ParameterError(f"pitch_cm must be positive, got {pitch_cm}")
        if element_size_cm is None:
            sy, sx = py, px
        else:
            size = np.broadcast_to(np.asarray(element_size_cm, dtype=np.float64), (2,))
            sy, sx = float(size[0]), float(size[1])
        if active is None:
            mask = np.ones((rows, cols), dtype=bool)
        else:
            mask = np.asarray(active, dtype=bool)
            if mask.shape != (rows, cols):
                raise ParameterError(
                    f"active: expected a ({rows}, {cols}) mask, got shape {mask.shape}"
                )
        if neighbour_gap < 0:
            raise ParameterError(f"neighbour_gap must be >= 0, got {neighbour_gap}")
        r, c = np.nonzero(mask)
        cells = r * cols + c
        xy = np.column_stack([(c + 0.5) * px, (r + 0.5) * py])
        return cls(
            xy,
            (sx, sy),
            shape=(rows, cols),
            cells=cells,
            pitch_cm=(py, px),
            neighbours=_grid_neighbours(rows, cols, r, c, neighbour_gap),
            regions=regions,
        )

    @classmethod
    def points(
        cls,
        xy_cm: npt.ArrayLike,
        *,
        size_cm: float | npt.ArrayLike = 1.0,
        area_cm2: npt.ArrayLike | None = None,
        names: Sequence[str] | None = None,
        neighbours: tuple[npt.ArrayLike, npt.ArrayLike] | None = None,
        regions: Mapping[str, npt.ArrayLike] | None = None,
    ) -> Layout:
        """Discrete sensors at arbitrary positions (no grid).

        Parameters
        ----------
        xy_cm : array_like, shape (N, 2)
            Centres in cm.
        size_cm : float or array_like, shape (2,) or (N, 2)
            Width and height in cm (a scalar means square elements).
        area_cm2 : array_like, optional
            Sensing area per element in cm² (default width x height).
        names : sequence of str, optional
            A name per element.
        neighbours : (indptr, indices), optional
            Neighbour graph for repair; none by default.
        regions : mapping, optional
            Named element groups.
        """
        xy = np.asarray(xy_cm, dtype=np.float64)
        size = np.asarray(size_cm, dtype=np.float64)
        if size.ndim == 0:
            size = np.array([float(size), float(size)])
        return cls(xy, size, area_cm2=area_cm2, names=names, neighbours=neighbours, regions=regions)

    # ------------------------------------------------------------------ properties
    @property
    def n_elements(self) -> int:
        """Number of elements N."""
        return int(self._xy.shape[0])

    def __len__(self) -> int:
        return self.n_elements

    @property
    def kind(self) -> str:
        """``"grid"`` or ``"points"``."""
        return "grid" if self._shape is not None else "points"

    @property
    def xy_cm(self) -> _FloatArray:
        """Element centres (N, 2) in cm."""
        return self._xy

    @property
    def size_cm(self) -> _FloatArray:
        """Element width and height (N, 2) in cm."""
        return self._size

    @property
    def area_cm2(self) -> _FloatArray:
        """Sensing area (N,) of each element in cm²."""
        return self._area

    @property
    def shape(self) -> tuple[int, int] | None:
        """Grid (rows, cols), or None for a points layout."""
        return self._shape

    @property
    def pitch_cm(self) -> tuple[float, float] | None:
        """Grid pitch (row pitch = y, column pitch = x) in cm, or None."""
        return self._pitch

    @property
    def cells(self) -> _IntArray | None:
        """Flat row-major grid cell of each element, or None for a points layout."""
        return self._cells

    @property
    def active(self) -> npt.NDArray[np.bool_] | None:
        """Boolean (rows, cols) mask of cells that hold an element, or None."""
        if self._shape is None or self._cells is None:
            return None
        m = np.zeros(self._shape[0] * self._shape[1], dtype=bool)
        m[self._cells] = True
        return m.reshape(self._shape)

    @property
    def names(self) -> tuple[str, ...] | None:
        """Element names, or None."""
        return self._names

    @property
    def neighbours(self) -> tuple[_IntArray, _IntArray]:
        """The 4-neighbour graph as (indptr, indices) compressed sparse rows."""
        return self._indptr, self._indices

    def neighbours_of(self, element: int) -> _IntArray:
        """Indices of the neighbours of ``element``."""
        return self._indices[self._indptr[element] : self._indptr[element + 1]]

    @property
    def regions(self) -> dict[str, _IntArray]:
        """Named regions: name -> element indices (a copy of the mapping)."""
        return dict(self._regions)

    @property
    def orientation(self) -> dict[str, str]:
        """What lies beyond each edge of the drawn map (edge -> label; a copy, empty when the
        layout declares none)."""
        # layouts pickled before the field existed (cached models) have none
        return dict(getattr(self, "_orientation", {}))

    def with_orientation(self, orientation: Mapping[str, str] | str | None) -> Layout:
        """A copy of this layout with ``orientation`` (a preset name of :data:`ORIENTATIONS`
        or edge -> label; None removes it)."""
        return self._replace(orientation=orientation)

    @property
    def extent_cm(self) -> tuple[float, float, float, float]:
        """Bounding box of the elements (x0, x1, y0, y1) in cm, including their size."""
        half = self._size / 2
        lo = (self._xy - half).min(axis=0) if self.n_elements else np.zeros(2)
        hi = (self._xy + half).max(axis=0) if self.n_elements else np.zeros(2)
        return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])

    # ------------------------------------------------------------------ grid views
    def element_at(self, row: int, col: int) -> int:
        """Index of the element in grid cell (row, col), or -1 if the cell is empty."""
        if self._shape is None or self._cells is None:
            raise ParameterError("element_at needs a grid layout")
        rows, cols = self._shape
        if not (0 <= row < rows and 0 <= col < cols):
            raise ParameterError(f"cell ({row}, {col}) is outside the {rows} x {cols} grid")
        hit = np.nonzero(self._cells == row * cols + col)[0]
        return int(hit[0]) if hit.size else -1

    def element_name(self, element: int) -> str:
        """How people name an element: its own name if the layout has names, else
        ``e17 (row 3, column 6)`` on a grid (the index from 0, as ``texsense health`` and the
        files count elements; row and column from 1 at the top left of the drawn map, as
        ``texsense health``, the report and the pages count them), else ``e17``."""
        if self._names is not None:
            return self._names[element]
        if self._shape is None or self._cells is None:
            return f"e{element}"
        row, col = divmod(int(self._cells[element]), self._shape[1])
        return f"e{element} (row {row + 1}, column {col + 1})"

    def to_grid(self, values: npt.ArrayLike, fill: float = np.nan) -> np.ndarray:
        """Arrange per-element values (..., N) as maps (..., rows, cols); empty cells = ``fill``."""
        if self._shape is None or self._cells is None:
            raise ParameterError("to_grid needs a grid layout; this layout holds discrete points")
        v = np.asarray(values)
        if v.shape[-1] != self.n_elements:
            raise ParameterError(
                f"to_grid: expected {self.n_elements} values in the last axis, got {v.shape[-1]}"
            )
        dtype = np.result_type(v.dtype, np.float32) if np.isnan(fill) else v.dtype
        out = np.full((*v.shape[:-1], self._shape[0] * self._shape[1]), fill, dtype=dtype)
        out[..., self._cells] = v
        return out.reshape(*v.shape[:-1], *self._shape)

    def from_grid(self, maps: npt.ArrayLike) -> np.ndarray:
        """Per-element values (..., N) from maps (..., rows, cols)."""
        if self._shape is None or self._cells is None:
            raise ParameterError("from_grid needs a grid layout")
        m = np.asarray(maps)
        if m.shape[-2:] != self._shape:
            raise ParameterError(f"from_grid: expected maps of shape {self._shape}, got {m.shape}")
        return m.reshape(*m.shape[:-2], -1)[..., self._cells]

    # ------------------------------------------------------------------ regions
    def with_regions(self, regions: Mapping[str, npt.ArrayLike]) -> Layout:
        """A copy of this layout with ``regions`` added (replacing equal names)."""
        merged: dict[str, Any] = {**self._regions, **regions}
        return self._replace(regions=merged)

    def equal_areas(self, n_areas: int) -> dict[str, _IntArray]:
        """Split the sensing area into equal rectangles and group the elements by them.

        Thesis §6.3.2 aggregates the seat into 4 and 16 equal areas. The bounding box of the
        elements is cut into a k x k grid (``n_areas = k²``); each element belongs to the
        rectangle holding its centre. Areas are named ``a1`` .. ``a{n}`` row-major from the
        top left.

        Parameters
        ----------
        n_areas : int
            A square number: 4, 16, 64, ...
        """
        k = round(float(np.sqrt(n_areas)))
        if k < 1 or k * k != n_areas:
            raise ParameterError(f"n_areas must be a square number (4, 16, ...), got {n_areas}")
        # worked out once per layout (the posture features ask for it on every live frame)
        cache = self.__dict__.setdefault("_equal_areas", {})
        if n_areas not in cache:
            x0, x1, y0, y1 = self.extent_cm
            ix = np.clip(((self._xy[:, 0] - x0) / (x1 - x0) * k).astype(int), 0, k - 1)
            iy = np.clip(((self._xy[:, 1] - y0) / (y1 - y0) * k).astype(int), 0, k - 1)
            area_index = iy * k + ix
            cache[n_areas] = {
                f"a{i + 1}": _readonly(np.nonzero(area_index == i)[0]) for i in range(n_areas)
            }
        return dict(cache[n_areas])

    # ------------------------------------------------------------------ (de)serialisation
    def _replace(self, **changes: Any) -> Layout:
        args: dict[str, Any] = {
            "xy_cm": self._xy,
            "size_cm": self._size,
            "area_cm2": self._area,
            "shape": self._shape,
            "cells": self._cells,
            "pitch_cm": self._pitch,
            "neighbours": (self._indptr, self._indices),
            "names": self._names,
            "regions": self._regions,
            "orientation": self.orientation,
        }
        args.update(changes)
        xy, size = args.pop("xy_cm"), args.pop("size_cm")
        return Layout(xy, size, **args)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able description that :meth:`from_dict` turns back into an equal layout."""
        return {
            "kind": self.kind,
            "xy_cm": self._xy.tolist(),
            "size_cm": self._size.tolist(),
            "area_cm2": self._area.tolist(),
            "shape": None if self._shape is None else list(self._shape),
            "cells": None if self._cells is None else self._cells.tolist(),
            "pitch_cm": None if self._pitch is None else list(self._pitch),
            "neighbours_indptr": self._indptr.tolist(),
            "neighbours_indices": self._indices.tolist(),
            "names": None if self._names is None else list(self._names),
            "regions": {k: v.tolist() for k, v in self._regions.items()},
            "orientation": self.orientation,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Layout:
        """Inverse of :meth:`to_dict`."""
        try:
            return cls(
                d["xy_cm"],
                d["size_cm"],
                area_cm2=d.get("area_cm2"),
                shape=None if d.get("shape") is None else tuple(d["shape"]),
                cells=d.get("cells"),
                pitch_cm=None if d.get("pitch_cm") is None else tuple(d["pitch_cm"]),
                neighbours=(d["neighbours_indptr"], d["neighbours_indices"]),
                names=d.get("names"),
                regions=d.get("regions") or {},
                orientation=d.get("orientation") or None,
            )
        except KeyError as e:
            raise ParameterError(f"layout description lacks the field {e.args[0]!r}") from None
        except ParameterError:
            raise
        except (OverflowError, TypeError, ValueError) as e:  # a description from a file:
            # a number beyond float64 (a 400-digit integer), text or a ragged list
            raise ParameterError(f"layout description: {e}") from None

    def __eq__(self, other: object) -> bool:
        """Equal geometry, topology, names and regions (the orientation only labels the
        drawing: it does not take part)."""
        if not isinstance(other, Layout):
            return NotImplemented
        return (
            np.array_equal(self._xy, other._xy)
            and np.array_equal(self._size, other._size)
            and np.array_equal(self._area, other._area)
            and self._shape == other._shape
            and self._pitch == other._pitch
            and (
                (self._cells is None and other._cells is None)
                or (
                    self._cells is not None
                    and other._cells is not None
                    and np.array_equal(self._cells, other._cells)
                )
            )
            and np.array_equal(self._indptr, other._indptr)
            and np.array_equal(self._indices, other._indices)
            and self._names == other._names
            and self._regions.keys() == other._regions.keys()
            and all(np.array_equal(v, other._regions[k]) for k, v in self._regions.items())
        )

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        if self._shape is not None:
            return (
                f"Layout.grid({self._shape[0]} x {self._shape[1]}, "
                f"{self.n_elements} elements, {len(self._regions)} regions)"
            )
        return f"Layout.points({self.n_elements} elements, {len(self._regions)} regions)"


def _grid_neighbours(
    rows: int, cols: int, r: _IntArray, c: _IntArray, gap: int
) -> tuple[_IntArray, _IntArray]:
    """The 4-neighbour graph (CSR) of the elements at rows ``r``, columns ``c`` of a grid:
    left, right, up, down in that order, each the nearest element at most ``gap`` empty cells
    away (whole-grid shifts: millions of cells take a few array passes, not a Python loop)."""
    n = r.size
    index = np.full((rows, cols), -1, dtype=np.int64)
    index[r, c] = np.arange(n)
    found = np.empty((n, 4), dtype=np.int64)
    for d, (dr, dc) in enumerate(((0, -1), (0, 1), (-1, 0), (1, 0))):
        nearest = np.full((rows, cols), -1, dtype=np.int64)
        for step in range(gap + 1, 0, -1):  # the farthest first: nearer ones overwrite
            sr, sc = dr * step, dc * step
            if abs(sr) >= rows or abs(sc) >= cols:
                continue
            # the cell (i, j) sees the element at (i + sr, j + sc)
            src = index[max(sr, 0) : rows + min(sr, 0), max(sc, 0) : cols + min(sc, 0)]
            dst = nearest[max(-sr, 0) : rows + min(-sr, 0), max(-sc, 0) : cols + min(-sc, 0)]
            np.copyto(dst, src, where=src >= 0)
        found[:, d] = nearest[r, c]
    linked = found >= 0
    indptr = np.concatenate(([0], np.cumsum(linked.sum(axis=1)))).astype(np.int64)
    return indptr, found[linked]


def whole_numbers(values: Any, what: str) -> _IntArray:
    """``values`` as int64 indices, or :class:`ParameterError` naming ``what``: whole numbers
    only. Indices come from files and messages (a layout line, HDF5 datasets, a device's
    announcement): a ``1.5`` is refused, not truncated, and ``inf``, ``NaN``, text or a
    number beyond int64 are refused, not a traceback."""
    try:
        a = np.asarray(values)
    except (ValueError, TypeError, OverflowError) as e:  # ragged lists, odd objects
        raise ParameterError(f"{what}: expected whole numbers ({e})") from None
    if a.size == 0:
        return np.zeros(a.shape, dtype=np.int64)
    limit = np.iinfo(np.int64).max
    if a.dtype.kind == "i" or (a.dtype.kind == "u" and int(a.max()) <= limit):
        return a.astype(np.int64, copy=False)
    flat = a.ravel()
    if a.dtype.kind == "f":
        whole = np.isfinite(flat) & (np.abs(np.nan_to_num(flat)) < 2.0**62)
        whole[whole] = flat[whole] == np.round(flat[whole])
        if whole.all():
            return a.astype(np.int64)
        raise ParameterError(f"{what}: expected whole numbers, found {flat[np.argmin(whole)]}")
    if a.dtype.kind == "u":
        raise ParameterError(f"{what}: expected whole numbers, found {flat.max()} (too large)")
    kinds = sorted({"an integer beyond int64" if type(v) is int else type(v).__name__
                    for v in flat[:1000].tolist()})  # fmt: skip
    raise ParameterError(f"{what}: expected whole numbers, found {', '.join(kinds)}")


def _grid_of(
    n: int,
    shape: tuple[int, int] | None,
    cells: npt.ArrayLike | None,
    pitch_cm: tuple[float, float] | None,
) -> tuple[tuple[int, int] | None, _IntArray | None, tuple[float, float] | None]:
    """The checked grid of a layout: its shape, the cell of every element, the pitch."""
    if (shape is None) != (cells is None):
        raise ParameterError("shape and cells must be given together")
    if pitch_cm is not None and shape is None:
        raise ParameterError("pitch_cm is only meaningful for a grid layout")
    if shape is None:
        return None, None, None
    dims = whole_numbers(shape, "shape")
    if dims.shape != (2,):
        raise ParameterError(f"shape: expected rows and cols, got {shape}")
    rows, cols = int(dims[0]), int(dims[1])
    if rows < 1 or cols < 1:
        raise ParameterError(f"shape: rows and cols must be >= 1, got {shape}")
    if rows * cols > MAX_EMPTY_CELLS + SPARSE_FACTOR * n:
        raise ParameterError(
            f"shape: a grid of {rows} x {cols} cells for {n} elements (a map of it would be "
            f"mostly empty; at most {SPARSE_FACTOR} cells per element plus {MAX_EMPTY_CELLS})"
        )
    c = whole_numbers(cells, "cells")
    if c.shape != (n,):
        raise ParameterError(f"cells: expected shape ({n},), got {c.shape}")
    if n and (c.min() < 0 or c.max() >= rows * cols):
        raise ParameterError(f"cells: indices must lie in 0..{rows * cols - 1}")
    ordered = np.sort(c)
    if np.any(ordered[1:] == ordered[:-1]):
        raise ParameterError("cells: two elements share one grid cell")
    pitch = None
    if pitch_cm is not None:
        try:  # a pair of real numbers (a file's layout may hold anything)
            pair = np.asarray(pitch_cm, dtype=np.float64)
        except (TypeError, ValueError, OverflowError):
            pair = np.zeros(0)
        if pair.shape != (2,):
            raise ParameterError(f"pitch_cm: expected two numbers, got {pitch_cm!r:.40}")
        pitch = (float(pair[0]), float(pair[1]))
        if not (MIN_CM <= pitch[0] <= MAX_CM and MIN_CM <= pitch[1] <= MAX_CM):
            raise ParameterError(f"pitch_cm must be {MIN_CM:g} to {MAX_CM:g} cm, got {pitch_cm}")
    return (rows, cols), _readonly(c), pitch


def _neighbours_of(
    n: int, neighbours: tuple[npt.ArrayLike, npt.ArrayLike] | None
) -> tuple[_IntArray, _IntArray]:
    """The checked neighbour graph (CSR: indptr, indices) of n elements (none by default)."""
    if neighbours is None:
        return np.zeros(n + 1, dtype=np.int64), np.zeros(0, dtype=np.int64)
    indptr = whole_numbers(neighbours[0], "neighbours: indptr")
    indices = whole_numbers(neighbours[1], "neighbours: indices")
    if indptr.shape != (n + 1,) or indptr[0] != 0 or np.any(np.diff(indptr) < 0):
        raise ParameterError(
            f"neighbours: indptr must be non-decreasing, start at 0, have {n + 1} entries"
        )
    if indices.shape != (indptr[-1],):
        raise ParameterError(f"neighbours: expected {indptr[-1]} indices")
    if indices.size and (indices.min() < 0 or indices.max() >= n):
        raise ParameterError(f"neighbours: indices must lie in 0..{n - 1}")
    return indptr, indices
