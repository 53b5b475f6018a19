"""A live frame of a pipeline of one compiled pass goes in one call (``Chain.step_at``, issue
34, sixteenth round): the chain checks the frame's time and takes the readings as given when
they are what it reads; anything else goes the way it went before (converted first). Over a
table of inputs, both ways give the same values, masks, codes, clock and errors, to the bit.
"""

from __future__ import annotations

import numpy as np
import pytest

from texsense.calibration.workflows import calibrate_mat, material_record
from texsense.compensation.drift import DriftModel, log_kernel
from texsense.compensation.pipeline import Pipeline
from texsense.compensation.stages import Drift, StageChain
from texsense.exceptions import ParameterError
from texsense.sim import protocols
from texsense.sim.failures import FailureModel
from texsense.sim.mat import VirtualMat

N = 16


@pytest.fixture(scope="module")
def stream():
    """A 16-element prototype's calibration (with a drift stage), layout, and a session with
    failures (float64)."""
    mat = VirtualMat.prototype(N, "textile-3mm", seed=4)
    ft = mat.cdc.frame_time_s(N)
    base = mat.scan(np.arange(8) * ft, np.zeros((8, N))).capacitance
    uni = mat.scan((8 + np.arange(8)) * ft, np.full((8, N), 1.0)).capacitance
    material = material_record(
        protocols.run_protocol("calibration", "textile-3mm", seed=9, sample_hz=None)
    )
    cal = calibrate_mat(material, base, uni, 1.0, 3.0)
    # with a drift stage, whose step depends on the time since the last frame
    cal = StageChain([*cal.stages, Drift.of(DriftModel(-0.03, log_kernel(), "log"))])
    session = VirtualMat.prototype(N, "textile-3mm", seed=4, failures=FailureModel())
    times = np.arange(60) * ft
    load = 1.5 + np.sin(times / 4.0)[:, None] * np.linspace(0.2, 1.0, N)[None, :]
    rec = session.scan(times, np.clip(load, 0, None)).capacitance
    frames = np.ascontiguousarray(rec.frames, dtype=np.float64)
    return cal, rec.layout, frames, rec.times, np.asarray(rec.valid)


class Sub(np.ndarray):
    """An ndarray subclass: not taken as given (np.asarray-like conversion first)."""


def _inputs(frame: np.ndarray, valid: np.ndarray) -> dict[str, tuple[object, object]]:
    """The ways a caller may hand a frame over: (readings, validity)."""
    wide = np.zeros(2 * N)
    wide[::2] = frame
    return {
        "float64 array, no validity": (frame.copy(), None),
        "float64 array, bool validity": (frame.copy(), valid.copy()),
        "float32 array": (frame.astype(np.float32), valid.copy()),
        "list": (frame.tolist(), valid.tolist()),
        "strided view": (wide[::2], valid.copy()),
        "big-endian": (frame.astype(">f8"), None),
        "subclass": (frame.copy().view(Sub), None),
        "masked array": (np.ma.MaskedArray(frame.copy()), None),
        "int validity": (frame.copy(), valid.astype(np.int64)),
        "strided validity": (frame.copy(), np.repeat(valid, 2)[::2]),
        "validity subclass": (frame.copy(), valid.copy().view(Sub)),
        "too short": (frame[:-1].copy(), None),
        "validity too short": (frame.copy(), valid[:-1].copy()),
        "two-dimensional": (frame.reshape(1, N).copy(), None),
        "read-only": (_read_only(frame), None),
    }


def _read_only(x: np.ndarray) -> np.ndarray:
    y = x.copy()
    y.flags.writeable = False
    return y


def _outcome(fn):
    """What a call gave: its result, or the class and message of what it raised."""
    try:
        return "ok", fn()
    except Exception as e:  # compared as data
        return type(e).__name__, str(e)


def _same(a, b) -> None:
    assert a[0] == b[0], (a, b)
    if a[0] != "ok":
        assert a[1] == b[1]
        return
    (va, oka), (vb, okb) = a[1], b[1]
    np.testing.assert_array_equal(va, vb)
    np.testing.assert_array_equal(oka, okb)


def test_every_way_of_handing_a_frame_over_gives_what_the_old_way_gave(stream):
    """Two pipelines walk the stream: one by ``step`` (one call where it can), the other by
    the way every frame went before (``_step``: converted, then ``step_new``); at every frame
    each input form of the table gives both the same values, mask, codes and clock, or the
    same error."""
    cal, lay, frames, times, valid = stream
    one, old = (
        Pipeline(cal, lay, repair="neighbour-mean"),
        Pipeline(cal, lay, repair="neighbour-mean"),
    )
    assert one._live is not None  # a pipeline of one compiled pass
    seen = set()
    for k in range(len(frames)):
        forms = _inputs(frames[k], valid[k])
        name = list(forms)[k % len(forms)]
        x, v = forms[name]
        got = _outcome(lambda: one.step(x, v, times[k]))  # noqa: B023
        want = _outcome(lambda: old._step(x, v, times[k], True))  # noqa: B023
        _same(got, want)
        seen.add((name, got[0]))
        if got[0] == "ok":
            np.testing.assert_array_equal(one.codes_, old.codes_)
        assert one._last_t == old._last_t
        assert one.snapshot() == old.snapshot()
    assert len(seen) == len(_inputs(frames[0], valid[0]))
    assert {s for _, s in seen} == {"ok", "ParameterError"}


@pytest.mark.parametrize(
    ("t", "why"),
    [
        (float("nan"), "must not decrease"),
        (float("inf"), "must not decrease"),
        (-1.0, "must not decrease"),  # before the last frame
        ("x", "could not convert"),
        (None, "or a real number"),
    ],
)
def test_a_time_it_cannot_take_is_the_same_error_and_steps_nothing(stream, t, why):
    cal, lay, frames, _, _ = stream
    for step in ("step", "_step"):
        pipe = Pipeline(cal, lay, repair="neighbour-mean")
        pipe.step(frames[0], None, 5.0)
        before = pipe.snapshot()
        call = getattr(pipe, step)
        with pytest.raises((ParameterError, TypeError, ValueError), match=why):
            call(frames[1], None, t) if step == "step" else call(frames[1], None, t, True)
        assert pipe.snapshot() == before and pipe._last_t == 5.0


def test_times_that_float_reads_step_as_before(stream):
    """A time the binding does not read as a number but ``float`` does (a string) still steps,
    as it did; numpy scalars and ints step in one call."""
    cal, lay, frames, _, _ = stream
    a, b = Pipeline(cal, lay, repair="neighbour-mean"), Pipeline(cal, lay, repair="neighbour-mean")
    for k, t in enumerate(["0.5", np.float32(1.0), 2, np.float64(2.5), np.int64(3)]):
        got = _outcome(lambda: a.step(frames[k], None, t))  # noqa: B023
        _same(got, _outcome(lambda: b._step(frames[k], None, t, True)))  # noqa: B023
        assert a._last_t == b._last_t == float(t)


def test_the_chain_steps_nothing_for_inputs_it_does_not_take_as_given(stream):
    cal, lay, frames, _, valid = stream
    pipe = Pipeline(cal, lay, repair="neighbour-mean")
    chain = pipe.compiled()
    assert chain.step_at(0.0, frames[0], None) is not None
    before = chain.snapshot()
    for name, (x, v) in _inputs(frames[1], valid[1]).items():
        if name.startswith("float64 array") or name == "read-only":
            continue
        assert chain.step_at(1.0, x, v) is None, name
        assert chain.snapshot() == before and chain.last_t == 0.0, name


def test_the_clock_is_the_chain_s_reset_and_restored_with_the_stream(stream):
    cal, lay, frames, times, _ = stream
    pipe = Pipeline(cal, lay, repair="neighbour-mean")
    for k in range(5):
        pipe.step(frames[k], None, times[k])
    assert pipe.compiled().last_t == pipe._last_t == times[4]
    state = pipe.snapshot()
    again = Pipeline(cal, lay, repair="neighbour-mean").restore(state)
    assert again._last_t == times[4]
    with pytest.raises(ParameterError, match="must not decrease"):
        again.step(frames[5], None, times[3])
    a, _ = again.step(frames[5], None, times[5])
    b, _ = pipe.step(frames[5], None, times[5])
    np.testing.assert_array_equal(a, b)
    pipe.reset()
    assert pipe._last_t is None and pipe.compiled().last_t is None
    pipe.step(frames[0], None, times[0])  # an earlier time is a new stream after a reset
