"""Family "what is written cannot be read back" (issue 32, item 5): a property test over every
writer x its reader with generated names (slashes, quotes, unicode, NUL, empty, very long),
layouts (grids with empty cells, points with names, 1 element, 1 x N, non-square),
0 to 5 frames, values (NaN, inf, negative, beyond any sensor) and labels.

A writer either refuses before writing (a ParameterError, no file) or writes a file that its
reader gives back exactly, as far as the format keeps it (documented per format: a Tekscan
export keeps the grid, the values and the times; a wide CSV all but labels and per-element
times), with the readings that cannot be real marked invalid as every reader does.
"""

from __future__ import annotations

import collections

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from texsense import Layout, Recording
from texsense.exceptions import ParameterError
from texsense.io import load, save
from texsense.io._base import impossible, plausible
from texsense.io.tekscan import TekscanReader

#: names people and vendors give (XSENSOR's regions have slashes) and names that break things
NAMES = ["", "/", "left/heel", "HX210/11 LF", ".", "..", "#0", "a\nb", "a\rb", "a\x00b",
         '"quoted"', "it's", "a,b", "\u2028", "𝔘nicode ü", "x" * 1000, " lead", "tail ",
         "\ud800", "name", "r1"]  # fmt: skip
names = st.one_of(st.sampled_from(NAMES), st.text(max_size=40))
UNITS = [("pressure", "N/cm2"), ("pressure", "kPa"), ("raw", "count"), ("capacitance", "pF"),
         ("force", "N")]  # fmt: skip
#: The table test reads what the property tests counted: one worker of ``pytest -n`` for all.
pytestmark = pytest.mark.xdist_group("roundtrip")
OUTCOMES: collections.Counter[str] = collections.Counter()


@st.composite
def layouts(draw):
    if draw(st.booleans()):
        rows, cols = draw(st.integers(1, 4)), draw(st.integers(1, 5))
        active = draw(st.lists(st.booleans(), min_size=rows * cols, max_size=rows * cols))
        mask = np.array(active).reshape(rows, cols)
        if not mask.any():
            mask[draw(st.integers(0, rows - 1)), draw(st.integers(0, cols - 1))] = True
        pitch = draw(st.sampled_from([1.0, 0.5, (2.0, 2.7), 1.27]))
        lay = Layout.grid(rows, cols, pitch_cm=pitch, active=mask)
    else:
        n = draw(st.integers(1, 6))
        xy = np.array([[k * 1.5, draw(st.sampled_from([0.0, 2.0]))] for k in range(n)])
        element_names = draw(st.none() | st.lists(names, min_size=n, max_size=n))
        lay = Layout.points(xy, size_cm=1.0, names=element_names)
    n = lay.n_elements
    regions = draw(st.dictionaries(names, st.lists(st.integers(0, n - 1), max_size=n), max_size=3))
    orientation = draw(st.sampled_from([None, "bed", "seat", {"top": "toes"}]))
    return lay.with_regions(regions).with_orientation(orientation)


@st.composite
def recordings(draw):
    lay = draw(layouts())
    n, t = lay.n_elements, draw(st.integers(0, 5))
    quantity, unit = draw(st.sampled_from(UNITS))
    values = st.floats(width=32, allow_nan=True, allow_infinity=True) | st.floats(0, 100, width=32)
    frames = np.array(draw(st.lists(values, min_size=n * t, max_size=n * t)), np.float32)
    times = np.cumsum(draw(st.lists(st.floats(1e-3, 10.0), min_size=t, max_size=t)))
    valid = np.array(draw(st.lists(st.booleans(), min_size=n * t, max_size=n * t)), bool)
    labels = {}
    for name in draw(st.lists(names, max_size=2, unique=True)):
        if draw(st.booleans()):
            labels[name] = np.array(draw(st.lists(names, min_size=t, max_size=t)), dtype=str)
        else:
            labels[name] = np.arange(t, dtype=np.float64)
    meta = draw(st.dictionaries(names, names | st.integers(-5, 5), max_size=2))
    return Recording(frames.reshape(t, n), times, lay, quantity, unit, valid=valid.reshape(t, n),
                     labels=labels, meta=meta)  # fmt: skip


def _expected_valid(rec: Recording, valid: np.ndarray) -> np.ndarray:
    return valid & plausible(rec.frames, rec.quantity)


def check_hdf5(rec: Recording, back: Recording) -> None:
    assert back._with(valid=rec.valid).equals(rec)
    assert np.array_equal(back.valid, _expected_valid(rec, rec.valid))
    assert back.layout.orientation == rec.layout.orientation


def check_wide(rec: Recording, back: Recording) -> None:
    kept = rec._with(labels={})
    assert back._with(valid=rec.valid).equals(kept)
    assert np.array_equal(back.valid, _expected_valid(rec, rec.valid))
    assert back.layout.orientation == rec.layout.orientation


def check_tekscan(rec: Recording, back: Recording) -> None:
    same = rec.to_unit(back.unit)
    if rec.unit == back.unit:  # written in kPa from N/cm² so that it reads back exactly
        assert np.array_equal(back.frames, same.frames, equal_nan=True)
    else:  # a file in kPa read in N/cm²: one conversion, rounded once to float32
        finite = np.isfinite(same.frames)
        assert np.array_equal(finite, np.isfinite(back.frames))
        np.testing.assert_array_max_ulp(back.frames[finite], same.frames[finite], maxulp=1)
    assert np.array_equal(back.times, rec.times)
    lay, got = rec.layout, back.layout
    assert (got.shape, got.pitch_cm) == (lay.shape, lay.pitch_cm)
    assert np.array_equal(got.cells, lay.cells)
    # a Tekscan file holds no validity: the reader judges it by its own rules (a raw count
    # is never negative there)
    expected = np.ones(same.frames.shape, dtype=bool)
    rules = impossible(same.frames, rec.quantity,
                       non_negative=rec.quantity in TekscanReader.non_negative)  # fmt: skip
    for mask in rules.values():
        expected &= ~mask
    assert np.array_equal(back.valid, expected)


WRITERS = {"hdf5": (".h5", check_hdf5), "wide-csv": (".csv", check_wide),
           "tekscan": (".asf", check_tekscan)}  # fmt: skip


@pytest.mark.parametrize("fmt", list(WRITERS))
@settings(
    max_examples=60,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(rec=recordings())
def test_what_texsense_writes_texsense_reads(fmt, rec, tmp_path_factory):
    suffix, check = WRITERS[fmt]
    folder = tmp_path_factory.mktemp("rt")
    path = folder / f"r{suffix}"
    try:
        save(rec, path, format=fmt)
    except ParameterError:
        assert list(folder.iterdir()) == [], "a refusal must come before anything is written"
        OUTCOMES[f"{fmt}: refused before writing"] += 1
        return
    check(rec, load(path, format=fmt))
    OUTCOMES[f"{fmt}: read back"] += 1


def test_the_round_trip_table(fault_row):
    """One row per writer for docs/reliability.md (after the property tests above ran)."""
    if not OUTCOMES:
        pytest.skip("the property tests did not run in this session")
    for fmt in WRITERS:
        done, refused = OUTCOMES[f"{fmt}: read back"], OUTCOMES[f"{fmt}: refused before writing"]
        detail = f"{done} read back exactly, {refused} refused before writing"
        case = f"{fmt} writer x reader, {done + refused} generated recordings"
        fault_row("round trip", case, "read back", detail, cases=done + refused)


@pytest.mark.parametrize("fmt", list(WRITERS))
def test_a_lone_surrogate_anywhere_is_refused_before_writing_or_read_back(fmt, tmp_path):
    """Every text a writer writes (meta keys and values, region and element names), holding a
    lone surrogate: refused before anything is written, or read back as it was (the wide CSV
    wrote the meta and layout JSON with the escape, which every reader refuses: the round
    trip's generated cases found the meta, then the region name)."""
    suffix, check = WRITERS[fmt]
    bad = "a\ud800b"
    lay = Layout.grid(1, 2)
    places = {
        "meta value": dict(meta={"note": bad}),
        "meta key": dict(meta={bad: 1}),
        "region name": dict(layout=Layout(lay.xy_cm, lay.size_cm, regions={bad: [0]})),
        "element name": dict(layout=Layout(lay.xy_cm, lay.size_cm, names=[bad, "e1"])),
    }
    for k, (place, change) in enumerate(places.items()):
        rec = Recording(np.ones((2, 2)), np.arange(2.0), change.get("layout", lay), "pressure",
                        "N/cm2", meta=change.get("meta", {}))  # fmt: skip
        folder = tmp_path / str(k)
        folder.mkdir()
        try:
            save(rec, folder / f"r{suffix}", format=fmt)
        except ParameterError:
            assert list(folder.iterdir()) == [], place
            continue
        check(rec, load(folder / f"r{suffix}", format=fmt))
