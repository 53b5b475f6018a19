"""The per-frame arithmetic a live mat runs around its compiled chain, compiled
(``texsense._core``: ``frame_bounds``, ``MotionTest``, ``exposure_advance``,
``first_off_scale``) against the numpy code it stands in for, which stays the reference
(``compiled = False``): the same bits on generated frames and streams — NaN, infinities,
negative values, repaired elements, empty mats, stillness and movement, skipped frames,
alerts opening and clearing.
"""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from texsense import Layout
from texsense.apps.alerts import ExposureTracker
from texsense.compensation.intervals import BAND_EDGES, HeldOut, bounds, frame_bounds
from texsense.compensation.inuse import InUseDrift

LAY = Layout.grid(8, 8)
U = np.linspace(0.0, 3.0, 301)
P = U**2
SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])

values = st.lists(
    st.one_of(
        st.floats(-5, 50, allow_nan=False),
        st.sampled_from([np.nan, np.inf, -np.inf, 0.0, -0.0, 0.1, 0.25, 4.0]),
    ),
    min_size=1,
    max_size=40,
)


@SETTINGS
@given(
    v=values,
    seed=st.integers(0, 2**32 - 1),
    drift=st.floats(0, 2),
    range_max=st.one_of(st.none(), st.floats(0.5, 30)),
    fixed=st.one_of(st.none(), st.floats(0.1, 5)),
    own_edges=st.booleans(),
)
def test_frame_bounds_are_numpys(v, seed, drift, range_max, fixed, own_edges):
    x = np.array(v)
    ok = np.random.default_rng(seed).random(x.size) < 0.7
    edges = (0.0, 0.3, 1.0, 5.0) if own_edges else BAND_EDGES
    rng = np.random.default_rng(seed + 1)
    held = HeldOut(edges, tuple(rng.uniform(0.01, 0.5, len(edges))), (50,) * len(edges))
    kw = {"range_max": range_max, "multiplier_value": fixed}
    lo, hi = frame_bounds(x, ok, 0.95, held, drift=drift, **kw)
    with np.errstate(invalid="ignore"):  # (inf x 0: NaN, both ways)
        ref = bounds(x[None, :], 0.95, held, drift=np.array([[drift]]), repaired=~ok[None, :], **kw)
    np.testing.assert_array_equal(lo, ref[0][0])
    np.testing.assert_array_equal(hi, ref[1][0])
    assert lo.tobytes() == ref[0][0].tobytes() and hi.tobytes() == ref[1][0].tobytes()


def blob(row: float, col: float, peak: float) -> np.ndarray:
    r, c = np.divmod(np.arange(64), 8)
    return peak * np.exp(-0.5 * ((r - row) ** 2 + (c - col) ** 2) / 1.5**2)


#: a stream: segments of (what, frames, row, col, peak); "still" holds a creeping blob
segments = st.lists(
    st.tuples(
        st.sampled_from(["still", "move", "empty", "breathe"]),
        st.integers(1, 30),
        st.floats(1, 6),
        st.floats(1, 6),
        st.floats(0.05, 3),
    ),
    min_size=1,
    max_size=8,
)


def inuse_stream(segs, seed: int):
    """Frames (x, ok, t) of a stream the segments describe: every 10 s, creeping while still,
    a few elements not measured (some NaN) now and then."""
    rng = np.random.default_rng(seed)
    t, frames = 0.0, []
    for what, n, row, col, peak in segs:
        for k in range(n):
            if what == "empty":
                x = np.abs(rng.normal(0, 0.01, 64))
            elif what == "move":
                x = blob(row + 0.3 * k, col - 0.2 * k, peak)
            else:
                wobble = 0.01 * np.sin(k) if what == "breathe" else 0.0
                x = blob(row, col, peak * (1 + wobble)) * (1 + 0.002 * k)
            ok = rng.random(64) > (0.1 if rng.random() < 0.3 else 0.0)
            if rng.random() < 0.1:
                x = x.copy()
                x[rng.integers(0, 64)] = np.nan
            frames.append((x, ok, t))
            t += 10.0
    return frames


@SETTINGS
@given(segs=segments, seed=st.integers(0, 2**32 - 1), settle=st.sampled_from([20.0, 60.0]))
def test_inuse_motion_is_numpys(segs, seed, settle):
    opts = {"settle_s": settle, "update_s": 30.0}
    ref = InUseDrift(U, P, LAY, **opts)
    ref.compiled = False
    fast = InUseDrift(U, P, LAY, **opts)
    for x, ok, t in inuse_stream(segs, seed):
        a, b = ref.step(x, ok, t), fast.step(x, ok, t)
        assert a.tobytes() == b.tobytes()
        assert (ref._still_since, ref._empty_since) == (fast._still_since, fast._empty_since)
    assert ref.state.to_dict() == fast.state.to_dict()
    assert ref._gain.tobytes() == fast._gain.tobytes()


def exposure_stream(seed: int, frames: int, bounded: bool):
    rng = np.random.default_rng(seed)
    t, out = 0.0, []
    level = rng.uniform(0, 1.5, 16)
    for _ in range(frames):
        if rng.random() < 0.05:  # a turn, getting up
            level = rng.uniform(0, 1.5, 16) * (rng.random() < 0.8)
        p = level + rng.normal(0, 0.05, 16)
        p[rng.random(16) < 0.05] = np.nan
        lo, hi = (p - 0.1, p + 0.1) if bounded else (None, None)
        t += float(rng.choice([1.0, 10.0, 30.0]))
        out.append((p, lo, hi, t, bool(rng.random() < 0.2), bool(rng.random() < 0.05)))
    return out


@SETTINGS
@given(
    seed=st.integers(0, 2**32 - 1),
    bounded=st.booleans(),
    possible=st.booleans(),
    waiting=st.booleans(),
)
def test_exposure_step_is_numpys(seed, bounded, possible, waiting):
    lay = Layout.grid(4, 4)
    trackers = []
    for compiled in (False, True):
        tr = ExposureTracker(lay, reposition_min=5, count_possible=possible)
        tr.compiled = compiled
        if waiting:
            tr.wait_for_empty()
        trackers.append(tr)
    for p, lo, hi, t, skipped, hold in exposure_stream(seed, 200, bounded):
        got = []
        for tr in trackers:
            tr.hold = hold
            got.append([e.to_dict() for e in tr.step(p, t, lo, hi, skipped=skipped)])
        assert got[0] == got[1]
        ref, fast = trackers
        for name in ("exposure_s", "_relief_s", "_loaded_last", "confident", "possible"):
            assert getattr(ref, name).tobytes() == getattr(fast, name).tobytes(), name
        assert [a.to_dict() for a in ref.alerts] == [a.to_dict() for a in fast.alerts]
        assert ref.seated == fast.seated


LAY32 = Layout.grid(32, 32)  # 64 blocks: numpy's sums are pairwise there, not plain


def _still_after(s: float, x1: np.ndarray, d: np.ndarray, ok: np.ndarray, compiled: bool):
    est = InUseDrift(U, P, LAY32)
    est.compiled = compiled
    est.step(x1, np.ones(x1.size, bool), 0.0)
    est.step(x1 + s * d, ok, 10.0)
    return est._still_since  # 10.0 when the second frame was still, None when it moved


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_inuse_motion_at_its_threshold(seed):
    """Where a change of the load is just the motion share (the sums' last bits decide): the
    compiled test moves where numpy's does, on both sides of the threshold."""
    rng = np.random.default_rng(seed)
    r, c = np.divmod(np.arange(1024), 32)
    row, col = rng.uniform(4, 28, 2)
    x1 = rng.uniform(0.5, 3) * np.exp(-((r - row) ** 2 + (c - col) ** 2) / 50) + 0.2
    x1 *= rng.uniform(0.5, 1.5, 1024)
    d = rng.normal(0, 0.3, 1024)
    ok = rng.random(1024) > 0.1
    lo, hi = 0.0, 1.0
    while _still_after(hi, x1, d, ok, False) is not None:
        hi *= 2
    while True:  # bisect to the two floats either side
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        lo, hi = (mid, hi) if _still_after(mid, x1, d, ok, False) is not None else (lo, mid)
    for s in (lo, hi, np.nextafter(lo, -1.0), np.nextafter(hi, 2 * hi)):
        assert _still_after(s, x1, d, ok, True) == _still_after(s, x1, d, ok, False)


def test_a_stations_pipeline_gives_numpys_bounds():
    """A station's pipeline (in-use drift, bounds at 95 %) stepped through a stream of the
    seat's calibration: the compiled bounds and estimator give the numpy reference's bits."""
    from texsense.calibration.workflows import seat_calibration
    from texsense.compensation.pipeline import Pipeline

    cal = seat_calibration()
    lay = next(s.layout for s in cal.stages if isinstance(getattr(s, "layout", None), Layout))
    ref = Pipeline(cal, lay, in_use=True, interval=0.95)
    ref.compiled_bounds = False
    assert ref.estimator is not None
    ref.estimator.compiled = False
    fast = Pipeline(cal, lay, in_use=True, interval=0.95)
    conv, rng = cal["convert"], np.random.default_rng(3)
    n = lay.n_elements
    for k in range(300):
        still = (k // 60) % 2  # a minute still, a minute moving
        mm = 1.0 + 0.8 * np.sin((0 if still else k) / 3 + np.arange(n) / 20) * (k > 20)
        cap = conv.offset_pF_ + conv.gain_ * np.interp(
            mm + 0.001 * k, conv.curve_compression_mm_, conv.curve_capacitance_pF_
        )
        valid = rng.random(n) > 0.03
        a, b = ref.step(cap, valid, 2.0 * k), fast.step(cap, valid, 2.0 * k)
        assert a[0].tobytes() == b[0].tobytes() and np.array_equal(a[1], b[1])
        assert ref.bounds_ is not None and fast.bounds_ is not None
        assert ref.bounds_[0].tobytes() == fast.bounds_[0].tobytes()
        assert ref.bounds_[1].tobytes() == fast.bounds_[1].tobytes()
    assert ref.in_use_status() == fast.in_use_status()


@SETTINGS
@given(
    n=st.integers(0, 300),
    bad=st.lists(
        st.tuples(
            st.integers(0, 299),
            st.sampled_from([np.nan, np.inf, -np.inf, 1e12 * (1 + 2**-52), -2e12, 1e300]),
        ),
        max_size=3,
    ),
    edge=st.sampled_from([1e12, -1e12, 0.0, -0.0]),
)
def test_the_first_time_off_scale_is_numpys(n, bad, edge):
    """``first_off_scale`` (the door of every live frame, ``off_scale``) against numpy's
    ``~(|t| <= limit)``: the same first index over lengths across its chunks of 64, with
    times not a number, infinite, just past the limit, and times at the limit (on it)."""
    from texsense._core import first_off_scale
    from texsense.data.times import MAX_TIME_S, off_scale

    t = np.linspace(-5.0, 5.0, n)
    if n:
        t[n // 2] = edge
    for at, value in bad:
        if at < n:
            t[at] = value
    off = ~(np.abs(t) <= MAX_TIME_S)
    want = int(np.argmax(off)) if off.any() else None
    assert first_off_scale(t, MAX_TIME_S) == want
    assert (off_scale(t) is None) == (want is None)
    assert off_scale(t[::-1]) == off_scale(np.ascontiguousarray(t[::-1]))  # a strided view
