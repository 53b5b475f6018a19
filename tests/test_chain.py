"""The compiled chain (crates/core/src/chain.rs) against the path it replaced
(tests/reference_pipeline.py): same failure codes, same masks, values to 1e-9, on the virtual
seat with the thesis's failure rates; streaming, chunked and batch runs agree."""

from __future__ import annotations

import numpy as np
import pytest

from reference_pipeline import ReferenceDetector, ReferencePipeline
from texsense import Layout, Recording
from texsense.calibration.workflows import seat_calibration
from texsense.compensation.health import FailureDetector
from texsense.compensation.pipeline import Pipeline
from texsense.compensation.stages import Convert, StageChain
from texsense.sim.failures import FailureModel
from texsense.sim.mat import VirtualMat


@pytest.fixture(scope="module")
def seat():
    """The 96-element virtual seat calibrated as a user would, and a 300-frame session on
    it with intermittent and permanent failures (thesis rates), loads that come and go."""
    cal = seat_calibration(mat_seed=5)
    mat = VirtualMat.seat(seed=5, failures=FailureModel())
    n = mat.layout.n_elements
    times = np.arange(300) * mat.cdc.frame_time_s(n)
    xy = mat.layout.xy_cm
    on = (np.sin(times / 40.0) > -0.3)[:, None]
    load = on * (0.4 + 2.2 * np.exp(-np.sum((xy - xy.mean(0)) ** 2, axis=1) / 60.0))[None, :]
    load = load * (1 + 0.2 * np.sin(times / 7.0))[:, None]
    scan = mat.scan(times, load)
    assert scan.failed.any() and (~scan.failed).any()
    # and 1 % of readings flagged by the converter (what detect=False has to go by)
    flagged = np.random.default_rng(2).random(scan.failed.shape) < 0.01
    rec = scan.capacitance
    return cal, rec._with(valid=rec.valid & ~flagged)


def test_compiled_detector_equals_the_numpy_detector():
    rng = np.random.default_rng(3)
    active = rng.random((9, 11)) > 0.3
    for lay in (Layout.grid(8, 7), Layout.grid(9, 11, active=active)):
        n = lay.n_elements
        base = rng.uniform(8, 12, n)
        top = base + rng.uniform(5, 10, n)
        frames = base + rng.uniform(0, 6, (200, n))
        frames[:, : n // 5] = frames[0, : n // 5]  # still elements (stuck while others move)
        frames[rng.random(frames.shape) < 0.03] = 0.0  # shorts
        frames[rng.random(frames.shape) < 0.01] = np.nan
        frames[rng.random(frames.shape) < 0.01] *= 3.0  # out of range
        valid = rng.random(frames.shape) > 0.02
        for base_pf, max_pf in ((base, top), (None, None)):
            ref = ReferenceDetector(lay, base_pf, max_pf, stuck_frames=5)
            expected = np.stack([ref.step(frames[k], valid[k]) for k in range(200)])
            assert set(np.unique(expected)) == {0, 1, 2, 3, 4} or max_pf is None
            det = FailureDetector(lay, stuck_frames=5).fit(base_pf, max_pf)
            np.testing.assert_array_equal(det.detect(frames, valid), expected)
            det.reset()
            stream = []
            for k in range(200):
                det.step(frames[k], valid[k], t=float(k))
                stream.append(det.codes_)
            np.testing.assert_array_equal(np.stack(stream), expected)


STAGES = [
    dict(repair=None),
    dict(repair="zero"),
    dict(repair="last-value"),
    dict(repair="neighbour-mean"),
    dict(repair="idw8"),
    dict(repair="harmonic"),
    dict(repair="neighbour-mean", drift=False),
    dict(repair="neighbour-mean", hysteresis=False),
    dict(repair="neighbour-mean", detect=False),
]


@pytest.mark.parametrize("stages", STAGES, ids=lambda s: ",".join(f"{k}={v}" for k, v in s.items()))
def test_compiled_pipeline_equals_the_old_path(seat, stages):
    cal, rec = seat
    lay = rec.layout
    cap = np.asarray(rec.frames, np.float64)
    expected, ok, codes = ReferencePipeline(cal, lay, **stages).run(cap, rec.valid, rec.times)
    pipe = Pipeline(cal, lay, **stages)
    got, got_ok, got_codes = pipe.process(cap, rec.times, rec.valid)
    np.testing.assert_array_equal(got_codes, codes)
    np.testing.assert_array_equal(got_ok, ok)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(expected))
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9, equal_nan=True)
    # the recording API gives the same (stored as float32)
    out = pipe.reset().run(rec)
    np.testing.assert_array_equal(out.valid, ok)
    np.testing.assert_array_equal(out.frames, got.astype(np.float32))
    assert (~ok).any() and np.isfinite(expected[ok]).all()


@pytest.mark.parametrize("repair", ["neighbour-mean", "idw8", "last-value", "harmonic"])
def test_streaming_chunked_and_batch_runs_agree(seat, repair):
    cal, rec = seat
    lay = rec.layout
    batch, *_ = Pipeline(cal, lay, repair=repair).process(rec.frames, rec.times, rec.valid)
    stream = Pipeline(cal, lay, repair=repair)
    rows = [stream.step(rec.frames[k], rec.valid[k], rec.times[k])[0] for k in range(rec.n_frames)]
    np.testing.assert_array_equal(np.array(rows), batch)
    chunked = Pipeline(cal, lay, repair=repair)
    parts = [
        chunked.process(rec.frames[a : a + 37], rec.times[a : a + 37], rec.valid[a : a + 37])[0]
        for a in range(0, rec.n_frames, 37)
    ]
    np.testing.assert_array_equal(np.concatenate(parts), batch)


def test_a_large_mat_runs_in_parallel_blocks_with_the_same_result(seat):
    """4096 elements x 40 frames crosses the parallel threshold of the core: the chain's
    blocks run on the thread pool, and frame-by-frame steps give the same numbers."""
    cal, _ = seat
    conv = cal["convert"]
    rng = np.random.default_rng(0)
    lay = Layout.grid(64, 64, pitch_cm=1.0)
    n = lay.n_elements
    offset, gain = rng.normal(0, 0.05, n), rng.normal(1, 0.03, n)
    big = StageChain([
        Convert(3.0).set_fitted(
            curve_compression_mm=conv.curve_compression_mm_,
            curve_capacitance_pF=conv.curve_capacitance_pF_, offset_pF=offset, gain=gain,
        ),
        cal["hysteresis"],
    ])  # fmt: skip
    t = np.arange(40) * 0.1
    e = 1.0 + 0.8 * np.sin(t[:, None] / 2 + np.arange(n)[None, :] / 40)
    cap = offset + gain * np.interp(e, conv.curve_compression_mm_, conv.curve_capacitance_pF_)
    cap[rng.random(cap.shape) < 0.02] = 0.0
    batch, ok, _ = Pipeline(big, lay, repair="neighbour-mean").process(cap, t)
    stream = Pipeline(big, lay, repair="neighbour-mean")
    rows = [stream.step(cap[k], None, t[k])[0] for k in range(t.size)]
    np.testing.assert_array_equal(np.array(rows), batch)
    assert (~ok).sum() > 1000 and np.isfinite(batch).all()


def test_chain_step_new_gives_what_run_gives_in_new_arrays(seat):
    """`Chain.step_new` (what `Pipeline.step` calls when the caller keeps its frames, issue 34
    ninth round): new arrays per frame with the values, codes and measured flags of `run`,
    none of them the array of another frame; a frame of the wrong shape is one ShapeError
    line."""
    from texsense.exceptions import ShapeError

    cal, rec = seat
    chain = Pipeline(cal, rec.layout, repair="neighbour-mean").compiled()
    dt = np.diff(rec.times, prepend=rec.times[0])
    frames = np.ascontiguousarray(rec.frames, dtype=np.float64)
    valid = rec.valid.copy()
    valid[::2] = True  # the frames stepped with None
    batch, codes = chain.run(dt, frames, valid)
    chain.reset()
    kept = []
    for k in range(rec.n_frames):
        out, got, measured = chain.step_new(dt[k], frames[k], valid[k] if k % 2 else None)
        assert (out.dtype, got.dtype, measured.dtype) == (np.float64, np.uint8, np.bool_)
        np.testing.assert_array_equal(out, batch[k])
        np.testing.assert_array_equal(got, codes[k])
        np.testing.assert_array_equal(measured, codes[k] == 0)
        kept.append(out)
    np.testing.assert_array_equal(np.stack(kept), batch)  # no frame overwritten by the next
    assert (codes != 0).any()
    for bad in (frames[0][:-1], frames[0][:1]):
        with pytest.raises(ShapeError) as e:
            chain.step_new(0.1, bad, None)
        assert "\n" not in str(e.value)
    with pytest.raises(ShapeError):
        chain.step_new(0.1, frames[0], np.ones(3, bool))


def test_chain_step_writes_what_run_gives_into_the_arrays_held(seat):
    """`Chain.step` (the live path of `Pipeline.step`, issue 34): one frame into arrays the
    caller holds gives the values and codes of `run`, frame after frame; an array of the
    wrong shape, or an output that is the input, is one ShapeError line; the pipeline hands
    out copies (a frame kept stays as it was after the next step), or with keep=False the
    arrays it holds (no copy per frame)."""
    from texsense.exceptions import ShapeError

    cal, rec = seat
    lay, n = rec.layout, rec.n_elements
    pipe = Pipeline(cal, lay, repair="neighbour-mean")
    chain = pipe.compiled()
    dt = np.diff(rec.times, prepend=rec.times[0])
    frames = np.ascontiguousarray(rec.frames, dtype=np.float64)
    valid = rec.valid.copy()
    valid[::2] = True  # the frames stepped with None
    batch, codes = chain.run(dt, frames, valid)
    chain.reset()
    out, got, measured = np.empty(n), np.empty(n, np.uint8), np.empty(n, bool)
    for k in range(rec.n_frames):
        chain.step(dt[k], frames[k], valid[k] if k % 2 else None, out, got, measured)
        np.testing.assert_array_equal(out, batch[k])
        np.testing.assert_array_equal(got, codes[k])
        np.testing.assert_array_equal(measured, codes[k] == 0)
    assert (codes != 0).any()
    for bad in (
        lambda: chain.step(0.1, frames[0][:-1], None, out, got, measured),
        lambda: chain.step(0.1, frames[0], None, np.empty(n + 1), got, measured),
        lambda: chain.step(0.1, out, None, out, got, measured),
    ):
        with pytest.raises(ShapeError) as e:
            bad()
        assert "\n" not in str(e.value)
    first, ok = pipe.step(rec.frames[0], None, rec.times[0])
    kept = first.copy(), ok.copy(), pipe.codes_.copy()
    pipe.step(rec.frames[1] * 0.0, None, rec.times[1])
    for a, b in zip((first, ok, pipe.codes_), kept, strict=True):
        assert a is not b
    np.testing.assert_array_equal(first, kept[0])
    np.testing.assert_array_equal(ok, kept[1])
    # keep=False (a caller that keeps nothing past the next step): the arrays held, no copies,
    # the same numbers as the copies of a pipeline stepped alike
    twin = Pipeline(cal, lay, repair="neighbour-mean")
    pipe.reset()
    held = None
    for k in range(3):
        want, want_ok = twin.step(rec.frames[k], None, rec.times[k])
        got, got_ok = pipe.step(rec.frames[k], None, rec.times[k], keep=False)
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(got_ok, want_ok)
        np.testing.assert_array_equal(pipe.codes_, twin.codes_)
        assert held is None or (got is held[0] and got_ok is held[1] and pipe.codes_ is held[2])
        held = got, got_ok, pipe.codes_


def test_pipeline_step_takes_arrays_as_given_or_converted_with_the_same_results(seat):
    """`Pipeline.step` hands float64 / bool arrays to the chain as given (issue 34 thirteenth
    round) and converts anything else first: a float32 frame, a frame not contiguous, a list,
    validity as integers, each gives the converted frame's values, codes and mask to the
    bit; a frame or validity of the wrong length is the pipeline's one-line ParameterError
    (not the chain's), and the state does not step on it; an output array handed back as
    the input (keep=False) is refused as before."""
    from texsense.exceptions import ParameterError, ShapeError

    cal, rec = seat
    lay, n = rec.layout, rec.n_elements
    given, twin = (Pipeline(cal, lay, repair="neighbour-mean") for _ in range(2))
    wide = np.ascontiguousarray(rec.frames, dtype=np.float64)
    strided = np.repeat(wide, 2, axis=1)[:, ::2]  # the same numbers, not contiguous
    for k in range(24):
        valid = rec.valid[k]
        frame = (rec.frames[k], strided[k], wide[k].tolist(), wide[k])[k % 4]
        flags = (valid, valid.astype(np.int8), None, valid)[k // 4 % 3]
        want_flags = None if flags is None else valid
        want, want_ok = twin.step(np.array(wide[k]), want_flags, rec.times[k])
        got, got_ok = given.step(frame, flags, rec.times[k])
        assert got.view(np.uint64).tolist() == want.view(np.uint64).tolist()
        np.testing.assert_array_equal(got_ok, want_ok)
        np.testing.assert_array_equal(given.codes_, twin.codes_)
    t = rec.times[24]
    for frame, flags, what in (
        (wide[24][:-1], None, "a frame of"),
        (wide[24], np.ones(n + 1, bool), "validity flags"),
        (wide[24:26], None, "a frame of"),
    ):
        with pytest.raises(ParameterError, match=what) as e:
            given.step(frame, flags, t)
        assert "\n" not in str(e.value)
    want, _ = twin.step(wide[24], None, t)
    got, _ = given.step(wide[24], None, t)  # the refused frames stepped nothing
    np.testing.assert_array_equal(got, want)
    held, _ = given.step(wide[25], None, rec.times[25], keep=False)
    with pytest.raises(ShapeError):
        given.step(held, None, rec.times[26], keep=False)


class _Refusals:
    """A compiled chain that counts what it refuses (``step``, ``step_new``, ``step_at``)."""

    def __init__(self, chain) -> None:
        self.chain, self.refused = chain, []

    def _call(self, name, *args):
        from texsense.exceptions import ShapeError

        try:
            return getattr(self.chain, name)(*args)
        except (TypeError, ShapeError) as e:
            self.refused.append(f"{name}: {type(e).__name__}: {e}")
            raise

    def step_new(self, *args):
        return self._call("step_new", *args)

    def step(self, *args):
        return self._call("step", *args)

    def step_at(self, *args):
        return self._call("step_at", *args)

    @property
    def last_t(self):
        return self.chain.last_t

    @last_t.setter
    def last_t(self, t):
        self.chain.last_t = t


def test_pipeline_step_hands_the_chain_only_arrays_it_reads(seat):
    """`Pipeline.step` checks up front what the chain reads (float64 / bool, 1-D,
    contiguous, of the mat's length) and converts anything else, or refuses it in its own
    words, before the chain sees it: the chain refuses nothing (before, it was handed every
    float64 / bool array and its TypeError or ShapeError caught); each frame gives the
    converted frame's values, codes and mask to the bit."""
    from texsense.exceptions import ParameterError

    cal, rec = seat
    lay, n = rec.layout, rec.n_elements
    given, twin = (Pipeline(cal, lay, repair="neighbour-mean") for _ in range(2))
    chain = given._live = _Refusals(given._live)
    wide = np.ascontiguousarray(rec.frames, dtype=np.float64)
    for k in range(12):
        valid = rec.valid[k]
        frame = (
            np.repeat(wide[k], 2)[::2],  # not contiguous
            wide[k][::-1].copy()[::-1],  # strides of -8
            wide[k].astype(">f8"),  # the other byte order
            wide[k][None, :],  # 2-D
            wide[k],
            wide[k],
        )[k % 6]
        flags = (valid, np.repeat(valid, 2)[::2], valid[::-1].copy()[::-1])[k // 2 % 3]
        want, want_ok = twin.step(np.array(wide[k]), valid.copy(), rec.times[k])
        if frame.ndim == 2:
            with pytest.raises(ParameterError, match="a frame of"):
                given.step(frame, flags, rec.times[k])
            frame = frame[0]
        got, got_ok = given.step(frame, flags, rec.times[k], keep=k % 2 == 0)
        assert got.view(np.uint64).tolist() == want.view(np.uint64).tolist()
        np.testing.assert_array_equal(got_ok, want_ok)
        np.testing.assert_array_equal(given.codes_, twin.codes_)
    t = rec.times[12]
    for frame, flags in ((wide[12][:-1], None), (wide[12], np.ones(n + 1, bool))):
        with pytest.raises(ParameterError):
            given.step(frame, flags, t)
    assert chain.refused == []


def test_run_f32_gives_runs_values_rounded_to_float32_bit_for_bit(seat):
    """`Chain.run_f32` (what `Pipeline.run` calls for a recording, issue 34 eleventh round):
    float32 readings widened a tile at a time, the values rounded to float32 — `run`'s
    values on the float32 readings, rounded, to the bit (NaN and infinite readings, readings
    flagged invalid, several tiles of frames, a batch in two calls); the codes the same."""
    cal, rec = seat
    n = rec.n_elements
    frames = np.tile(rec.frames, (6, 1))  # 1800 x 96: two tiles of 2**17 samples
    frames[7, :5] = [np.nan, np.inf, -np.inf, 1e30, -0.0]
    frames[700, 10:12] = np.nan
    valid = np.tile(rec.valid, (6, 1))
    valid[900:905, 20:40] = False
    assert frames.dtype == np.float32 and frames.size > 2**17
    dt = np.full(len(frames), float(rec.times[1] - rec.times[0]))
    dt[0] = 0.0
    pipe = Pipeline(cal, rec.layout, repair="neighbour-mean")
    chain = pipe.compiled()
    want, want_codes = chain.run(dt, frames.astype(np.float64), valid)
    chain.reset()
    got, codes = chain.run_f32(dt, frames, valid)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got.view(np.uint32), want.astype(np.float32).view(np.uint32))
    np.testing.assert_array_equal(codes, want_codes)
    assert (codes != 0).sum() > 100
    chain.reset()
    parts = [chain.run_f32(dt[a : a + 1000], frames[a : a + 1000], valid[a : a + 1000])[0]
             for a in (0, 1000)]  # fmt: skip
    np.testing.assert_array_equal(np.concatenate(parts).view(np.uint32), got.view(np.uint32))
    # the pipeline's recording path: the values process gives, stored as float32
    long = Recording(frames, np.cumsum(dt), rec.layout, rec.quantity, rec.unit, valid=valid)
    values, ok, found = Pipeline(cal, rec.layout, repair="neighbour-mean").process(
        frames, long.times, valid
    )
    out = pipe.reset().run(long)
    np.testing.assert_array_equal(
        out.frames.view(np.uint32), values.astype(np.float32).view(np.uint32)
    )
    np.testing.assert_array_equal(out.valid, ok)
    np.testing.assert_array_equal(pipe.codes_, found)
    assert chain.run_f32(dt[:0], frames[:0], valid[:0])[0].shape == (0, n)
