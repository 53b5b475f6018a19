"""The one base of every recording reader: a file is a **header** (layout, quantity and unit,
metadata, how many frames it declares), then **frames read in blocks** (the MNE pattern: the
base does everything that is not specific to a format).

A format's reader subclasses :class:`RecordingReader` and writes two methods:

- ``_read_header()`` parses the header and returns a :class:`Header`;
- ``_frames()`` yields one :class:`FrameRow` per frame (text formats), or ``_pieces()`` yields
  :class:`Piece` blocks of frames (HDF5); either calls ``_cut(message)`` when the file holds
  less than it declares (a last frame cut mid-line, fewer frames than the header says), and
  stops.

The base converts the values to texsense's unit, marks impossible readings invalid (not a
number, infinite or beyond float32, negative where the quantity cannot be negative: the
:class:`~texsense.Recording`'s ``valid`` mask), refuses times that go backwards (naming the
line) or lie on a scale no clock has (:mod:`texsense.data.times`), cuts the frames into blocks
of the requested length and, at the end, either refuses a file that was cut short
(:class:`~texsense.exceptions.FormatError`) or, with
``accept_truncated=True`` (``--accept-truncated`` on the command line), reads what is there and
says how much is missing in one warning line. Invalid readings are counted and reported in one
warning line too.

Examples
--------
>>> from texsense.io import open_reader
>>> with open_reader("../shared/data/vendor-formats/iscan_test.csv") as reader:
...     print(reader.header.layout.shape, reader.header.declared_frames)
...     print([block.n_frames for block in reader.blocks(100)])
(28, 28) 309
[100, 100, 100, 9]
"""

from __future__ import annotations

import collections
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, NamedTuple, Self

import numpy as np
import numpy.typing as npt

from texsense._progress import check_stopping, logger
from texsense.data import budget, units
from texsense.data.layout import BYTES_PER_CELL, Layout
from texsense.data.recording import Recording
from texsense.data.times import TimeCheck
from texsense.exceptions import FormatError, ParameterError, ShapeError, UnitError
from texsense.io._registry import Probe, register_reader
from texsense.io._text import Line, TextLines

__all__ = [
    "CEILING",
    "NON_NEGATIVE",
    "BlockReader",
    "FrameRow",
    "Header",
    "Piece",
    "RecordingReader",
    "check_declared_size",
    "impossible",
    "plausible",
]

#: Quantities whose readings cannot be negative: a negative reading is invalid.
NON_NEGATIVE = frozenset({"pressure", "capacitance", "force", "resistance"})
#: The largest magnitude a reading of a quantity can have, in texsense's unit (pressure in
#: N/cm², capacitance in pF, force in N, resistance in ohm): orders of magnitude beyond any
#: sensor (1 GPa, 1 mF, 10 MN), small enough that sums over a frame stay finite in float32.
#: A larger reading is invalid ("beyond any sensor").
CEILING = {"pressure": 1e5, "capacitance": 1e9, "force": 1e7, "resistance": 1e13}
#: The ceiling of every other quantity (raw counts, lengths, ...).
CEILING_OTHER = 1e15

#: The hint every "cut short" error ends with.
ACCEPT_HINT = "--accept-truncated (accept_truncated=True) reads the {n} complete {what}(s)"


@dataclass
class Header:
    """What a recording file says about itself before its frames.

    Attributes
    ----------
    layout : Layout
        The elements.
    quantity, unit : str
        What the frames hold once read (texsense's unit, e.g. N/cm² for pressure).
    meta : dict
        Provenance (source file, format, the file's own header keys, ...).
    source_unit : str, optional
        The unit of the values in the file, when it is not ``unit`` (converted on reading).
    declared_frames : int, optional
        How many frames the file says it holds (Tekscan ``START_FRAME``/``END_FRAME``, a
        texsense wide CSV's ``# frames:``, HDF5 dataset lengths), if it says.
    label_dtypes : dict
        The per-frame labels and their dtypes.
    element_times : bool
        Whether the frames carry per-element time stamps.
    """

    layout: Layout
    quantity: str
    unit: str
    meta: dict[str, Any]
    source_unit: str | None = None
    declared_frames: int | None = None
    label_dtypes: dict[str, Any] = field(default_factory=dict)
    element_times: bool = False


class FrameRow(NamedTuple):
    """One frame as a text reader parsed it: values in the file's unit, time in s, the line
    where the frame starts, its labels and, if the file has one, its validity mask."""

    values: npt.NDArray[Any]
    time: float
    line: int
    labels: dict[str, Any]
    valid: npt.NDArray[np.bool_] | None = None


@dataclass
class Piece:
    """A block of consecutive frames before the base's checks (values in the file's unit)."""

    values: npt.NDArray[Any]
    times: npt.NDArray[np.float64]
    labels: dict[str, npt.NDArray[Any]]
    lines: npt.NDArray[np.int64] | None = None
    #: the file's own validity mask (HDF5, texsense wide CSV); None: judged from the values
    valid: npt.NDArray[np.bool_] | None = None
    element_times: npt.NDArray[np.float64] | None = None


def impossible(
    values: npt.NDArray[np.floating[Any]], quantity: str, *, non_negative: bool = False
) -> dict[str, npt.NDArray[np.bool_]]:
    """The readings that cannot be real, by reason: not a number, infinite (or beyond
    float32), negative for a quantity of :data:`NON_NEGATIVE` (or with ``non_negative``),
    beyond the quantity's :data:`CEILING`. Every reader marks them invalid, whatever the file
    says about them. The least and the greatest value (NaN if there is one) spare the masks
    when all are plausible.

    >>> import numpy as np
    >>> {k: v.tolist() for k, v in impossible(np.array([1.0, -5, 3e38]), "pressure").items()}
    {'negative': [False, True, False], 'beyond any sensor': [False, False, True]}
    """
    out: dict[str, npt.NDArray[np.bool_]] = {}
    lo, hi = (values.min(), values.max()) if values.size else (0.0, 0.0)
    if not (np.isfinite(lo) and np.isfinite(hi)):
        out["not a number"] = np.isnan(values)
        out["infinite or beyond float32"] = np.isinf(values)
    if (non_negative or quantity in NON_NEGATIVE) and not lo >= 0:
        with np.errstate(invalid="ignore"):
            out["negative"] = values < 0
    ceiling = CEILING.get(quantity, CEILING_OTHER)
    if not (-ceiling <= lo and hi <= ceiling):
        with np.errstate(invalid="ignore"):
            out["beyond any sensor"] = np.abs(values) > ceiling
    return out


def plausible(values: npt.NDArray[np.floating[Any]], quantity: str) -> npt.NDArray[np.bool_]:
    """True where a reading of ``quantity`` can be real (see :func:`impossible`)."""
    ok = np.ones(np.shape(values), dtype=bool)
    for mask in impossible(values, quantity).values():
        ok &= ~mask
    return ok


def check_declared_size(
    path: Path,
    what: str,
    count: int,
    min_bytes_each: int,
    line: int | None = None,
    memory_each: int = BYTES_PER_CELL,
) -> None:
    """Refuse a header number that the file cannot hold (``Rows,1000000000`` in a 2 MB
    file) or that needs more memory than the budget (``ROWS 3000 COLS 3000``: a layout of 9 M
    elements), before anything is allocated or parsed from it: ``what`` declares ``count``
    values of at least ``min_bytes_each`` bytes each in the file and ``memory_each`` bytes
    each in memory (by default a layout's element, :data:`texsense.data.layout.BYTES_PER_CELL`)."""
    size = path.stat().st_size
    if count < 0 or count * min_bytes_each > size:
        raise FormatError(
            path,
            f"{what} declares {count} values, more than a file of {size} bytes can hold "
            "(a damaged header?)",
            line,
        )
    budget.check(count * memory_each, f"{what} (line {line})" if line else what, path)


class BlockReader:
    """What every reader shares: the file, the ``accept_truncated`` choice, noting a
    shortfall (:meth:`_cut`) and, at the end, refusing or reporting it (:meth:`_finish_cut`).

    Parameters
    ----------
    path : str or Path
        The file or folder.
    accept_truncated : bool
        Read a file that holds less than it declares (cut short, closed early) up to its last
        complete frame and warn, instead of refusing it.
    """

    #: the name of the format (``texsense.io.READER_CLASSES``)
    format: ClassVar[str] = ""

    def __init__(self, path: str | Path, *, accept_truncated: bool = False) -> None:
        self.path = Path(path)
        self.accept_truncated = bool(accept_truncated)
        self._shortfall: str | None = None

    def _cut(self, message: str) -> None:
        """Note that the file holds less than it declares (``message`` says what and how
        much); the format's reader then stops."""
        self._shortfall = message

    def _bad_line(self, line: Line, message: str) -> None:
        """A line that does not parse: the end of a file cut mid-line when it is the last
        line and has no line end, an error naming the line otherwise."""
        if line.ended:
            raise FormatError(self.path, message, line.number)
        self._cut(f"truncated: the file ends in the middle of line {line.number}")

    def _finish_cut(self, count: int, what: str = "frame") -> None:
        """Refuse (or, accepting, report in one line) a noted shortfall."""
        if self._shortfall is None:
            return
        if not self.accept_truncated:
            raise FormatError(
                self.path, f"{self._shortfall}; {ACCEPT_HINT.format(n=count, what=what)}"
            )
        logger.warning(
            "warning: %s: %s; read the %d complete %s(s) before it",
            self.path,
            self._shortfall,
            count,
            what,
        )

    #: the text file a line-oriented reader holds open (closed by :meth:`close`)
    _lines: TextLines | None = None

    @property
    def lines(self) -> TextLines:
        """The text file a line-oriented reader opened in its constructor."""
        if self._lines is None:
            raise RuntimeError(f"{type(self).__name__} reads no text file")
        return self._lines

    def close(self) -> None:
        """Release the file (the text file in ``_lines``; a format that holds another kind
        of file overrides this)."""
        if self._lines is not None:
            self._lines.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class RecordingReader(BlockReader):
    """A recording file opened for reading: its :attr:`header`, then :meth:`blocks` of frames
    (constant memory) or :meth:`read` (the whole :class:`~texsense.Recording`).

    Parameters
    ----------
    path : str or Path
        The file or folder.
    accept_truncated : bool
        Read a file that holds less than it declares (cut short, closed early) up to its last
        complete frame and warn, instead of refusing it.

    Attributes
    ----------
    header : Header
        Parsed on opening.
    frames_read : int
        Frames yielded so far.
    invalid : collections.Counter
        Readings marked invalid so far, by reason.
    """

    #: quantities whose readings this format cannot hold negative (in addition to NON_NEGATIVE)
    non_negative: ClassVar[frozenset[str]] = frozenset()
    #: bytes of memory per value while a whole file is read (:meth:`read`): a text reader
    #: parses float64 rows, stacks them and converts them to float32 with a validity mask
    bytes_per_value: ClassVar[int] = 22
    #: what the format is, in a few words (the table of formats, help and errors)
    what: ClassVar[str] = ""
    #: when format detection asks this reader (lower first: a specific rule before a loose one)
    sniff_order: ClassVar[int] = 100

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """A subclass that names its format is registered (:mod:`texsense.io._registry`)."""
        super().__init_subclass__(**kwargs)
        if cls.__dict__.get("format"):
            register_reader(cls)

    @classmethod
    def sniff(cls, probe: Probe) -> bool:
        """Whether the file (or folder) ``probe`` describes is of this format, by content."""
        return False

    def __init__(self, path: str | Path, *, accept_truncated: bool = False) -> None:
        super().__init__(path, accept_truncated=accept_truncated)
        self.frames_read = 0
        #: frames known to be complete when the header already shows a shortfall
        self._known_complete: int | None = None
        self.invalid: collections.Counter[str] = collections.Counter()
        self._times = TimeCheck(self.path)
        self._block = 4096
        #: the most frames :meth:`read` holds before the memory budget is exceeded
        self._max_frames = 1 << 62
        try:
            self.header = h = self._read_header()
            # what the header says must make a recording (quantity, unit, meta)
            n = h.layout.n_elements
            Recording(np.zeros((0, n)), [], h.layout, h.quantity, h.unit, meta=h.meta)
        except (ParameterError, ShapeError, UnitError) as e:
            self.close()
            raise FormatError(self.path, str(e)) from None
        except BaseException:
            self.close()
            raise
        self._factor = 1.0 if h.source_unit is None else units.factor(h.source_unit, h.unit)
        if self._shortfall is not None and not self.accept_truncated:
            self.close()  # the header already shows the file holds less than it declares
            self._finish_cut(self._known_complete or 0)

    # ------------------------------------------------------------------ for the formats
    def _read_header(self) -> Header:
        raise NotImplementedError

    def _frames(self) -> Iterator[FrameRow]:
        raise NotImplementedError

    def _pieces(self) -> Iterator[Piece]:
        """Blocks of frames; by default :meth:`_frames` grouped by the block length."""
        rows: list[FrameRow] = []
        for row in self._frames():
            check_stopping()
            rows.append(row)
            if len(rows) > self._max_frames:
                self._over_budget(len(rows))
            if len(rows) == self._block:
                yield self._stack(rows)
                rows = []
        if rows:
            yield self._stack(rows)

    def _stack(self, rows: list[FrameRow]) -> Piece:
        dtypes = self.header.label_dtypes
        return Piece(
            np.stack([r.values for r in rows]),
            np.array([r.time for r in rows], dtype=np.float64),
            {k: np.array([r.labels[k] for r in rows], dtype=dt) for k, dt in dtypes.items()},
            lines=np.array([r.line for r in rows], dtype=np.int64),
            valid=None if rows[0].valid is None else np.stack([_mask(r) for r in rows]),
        )

    def _impossible(self, values: npt.NDArray[np.float32]) -> dict[str, npt.NDArray[np.bool_]]:
        """Readings that cannot be real, by reason (a format can add its own). The least and
        the greatest value (NaN if there is one) spare the masks when all are plausible."""
        quantity = self.header.quantity
        return impossible(values, quantity, non_negative=quantity in self.non_negative)

    # ------------------------------------------------------------------ the base's work
    def _checked(self, piece: Piece, *, running: bool = True) -> Piece:
        """The piece in texsense's unit with its impossible readings invalid; ``running``:
        part of the pass from the start (invalid readings counted, times checked against
        the previous piece's), else a piece read out of order (:meth:`frames_at`)."""
        values = piece.values
        with np.errstate(over="ignore", invalid="ignore"):  # beyond float32: invalid readings
            if self._factor != 1.0:
                values = values.astype(np.float64) * self._factor
            frames = np.ascontiguousarray(values, dtype=np.float32)
        # what the file marks valid (all, if it has no mask) less the impossible readings,
        # which are invalid whatever the file says (an HDF5 frame of inf under valid = True)
        valid = np.ones(frames.shape, bool) if piece.valid is None else piece.valid.astype(bool)
        for reason, mask in self._impossible(frames).items():  # each reading counted once
            new = mask & valid
            count = int(np.count_nonzero(new))
            if count:
                if running:
                    self.invalid[reason] += count
                valid &= ~new
        if running:
            self._check_times(piece)
        return Piece(frames, piece.times, piece.labels, piece.lines, valid, piece.element_times)

    def _check_times(self, piece: Piece) -> None:
        """The piece's times: numbers, not going back, on a clock's scale (:mod:`texsense.data.
        times`, the one check of every reader's times; its end in :meth:`_finish`)."""
        self._times.block(piece.times, piece.lines, piece.element_times)

    def _recording(self, p: Piece) -> Recording:
        h = self.header
        return Recording(
            p.values,
            p.times,
            h.layout,
            h.quantity,
            h.unit,
            valid=p.valid,
            element_times=p.element_times,
            labels=p.labels,
            meta=h.meta,
        )

    def _finish(self) -> None:
        """At the end: refuse or report a shortfall, report invalid readings."""
        n = self.frames_read
        self._finish_cut(n)
        self._times.finish()
        total = sum(self.invalid.values())
        if total:
            parts = ", ".join(f"{c} {reason}" for reason, c in self.invalid.items() if c)
            logger.warning(
                "warning: %s: %d reading(s) marked invalid (%s) of %d",
                self.path,
                total,
                parts,
                n * self.header.layout.n_elements,
            )

    def _checked_pieces(self) -> Iterator[Piece]:
        for piece in self._pieces():
            check_stopping()
            checked = self._checked(piece)
            self.frames_read += checked.times.size
            if self.frames_read > self._max_frames:  # read() holds them all
                self._over_budget(self.frames_read)
            yield checked

    # ------------------------------------------------------------------ public
    def blocks(self, frames: int = 4096) -> Iterator[Recording]:
        """Yield the recording as :class:`~texsense.Recording` blocks of ``frames`` frames
        (the last may be shorter); memory stays flat in the file's length.

        Raises
        ------
        FormatError
            On a malformed line or field, a time that goes back, or (at the end) a file cut
            short without ``accept_truncated``.
        """
        if frames < 1:
            raise ParameterError(f"frames per block must be >= 1, got {frames}")
        self._block = int(frames)
        held: list[Piece] = []
        count = 0
        for piece in self._checked_pieces():
            held.append(piece)
            count += piece.times.size
            while count >= self._block:
                block, held = _split(held, self._block)
                count -= self._block
                yield self._recording(block)
        self._finish()
        if count:
            yield self._recording(_join(held))

    def frames_at(self, start: int, stop: int) -> Piece:
        """Frames ``start:stop`` read out of order (values in texsense's unit, impossible
        readings invalid, as in every block; no labels): what a player seeking in a long
        recording reads (:mod:`texsense.io.lazy`).

        Their times are checked as every block's are, within the frames read (numbers, not
        going back, on a clock's scale: :class:`~texsense.data.times.TimeCheck`; a file changed
        since its timeline was read is refused here, not shown).

        Raises
        ------
        FormatError
            For a format that is read from its start only (every text format), or for a time
            no clock has (naming the frame).
        """
        piece = self._checked(self._piece(start, stop), running=False)
        check = TimeCheck(self.path)
        check.count = start  # frames are named by their place in the file
        check.block(np.asarray(piece.times, dtype=np.float64), None, piece.element_times)
        return piece

    def _piece(self, start: int, stop: int) -> Piece:
        raise FormatError(self.path, f"a {self.what} is read from its start only, not in parts")

    def _expected_frames(self) -> int | None:
        """The frames :meth:`read` will read, if the file proves it before they are read
        (HDF5: what every dataset holds); a text file's declared count is only a claim (a file
        cut short is said as such), so text readers count the frames as they come."""
        return None

    def _frame_bytes(self) -> int:
        """Memory per frame while :meth:`read` holds the whole file."""
        h = self.header
        n = h.layout.n_elements
        per_value = self.bytes_per_value + (8 if h.element_times else 0)
        return n * per_value + 8 * (1 + len(h.label_dtypes)) + 400  # + objects per frame

    def _over_budget(self, frames: int) -> None:
        n = self.header.layout.n_elements
        budget.check(
            frames * self._frame_bytes(), f"reading {frames} frames of {n} elements", self.path,
            "a recording this long is read in blocks ('texsense process', texsense.io.open_reader)",
        )  # fmt: skip

    def read(self) -> Recording:
        """The whole recording (all frames in memory).

        Raises
        ------
        FormatError
            Also when the frames (as declared, or as read so far) need more memory than the
            budget (:mod:`texsense.data.budget`); :meth:`blocks` reads any length.
        """
        expected = self._expected_frames()
        if expected:
            self._over_budget(expected)
        self._max_frames = max(1, budget.max_memory() // self._frame_bytes())
        self._block = 1 << 62  # one piece: no copy to join blocks
        pieces = list(self._checked_pieces())
        self._finish()
        if not pieces:
            h = self.header
            n = h.layout.n_elements
            return Recording(
                np.zeros((0, n), np.float32),
                np.zeros(0),
                h.layout,
                h.quantity,
                h.unit,
                labels={k: np.zeros(0, dtype=dt) for k, dt in h.label_dtypes.items()},
                meta=h.meta,
            )
        return self._recording(_join(pieces))


def _mask(row: FrameRow) -> npt.NDArray[np.bool_]:
    """The validity mask of a row of a format whose rows all carry one."""
    if row.valid is None:
        raise RuntimeError(f"the row of line {row.line} has no validity mask, the first had one")
    return row.valid


def _join(pieces: list[Piece]) -> Piece:
    if len(pieces) == 1:
        return pieces[0]
    first = pieces[0]

    def cat(name: str) -> Any:
        parts = [getattr(p, name) for p in pieces]
        return None if parts[0] is None else np.concatenate(parts)

    return Piece(
        cat("values"),
        cat("times"),
        {k: np.concatenate([p.labels[k] for p in pieces]) for k in first.labels},
        cat("lines"),
        cat("valid"),
        cat("element_times"),
    )


def _split(pieces: list[Piece], n: int) -> tuple[Piece, list[Piece]]:
    """The first ``n`` frames of ``pieces`` as one piece, and the rest."""
    whole = _join(pieces)

    def part(sl: slice) -> Piece:
        def take(a: Any) -> Any:
            return None if a is None else a[sl]

        return Piece(
            whole.values[sl],
            whole.times[sl],
            {k: v[sl] for k, v in whole.labels.items()},
            take(whole.lines),
            take(whole.valid),
            take(whole.element_times),
        )

    rest = part(slice(n, None))
    return part(slice(0, n)), ([rest] if rest.times.size else [])
