"""The SIMD paths of the compiled core (issue 34) against its scalar kernels, through the
binding: the Preisach bank and the whole pipeline give the same numbers bit for bit on both
paths, on histories with NaN, infinities, readings out of range and readings flagged invalid
(the Rust property tests in crates/core cover the kernels on random tables and stacks)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest

from texsense import Layout, _core
from texsense.calibration.workflows import seat_calibration
from texsense.compensation.pipeline import Pipeline
from texsense.compensation.stages import Convert, StageChain

_, BEST = _core.simd_path()
pytestmark = pytest.mark.skipif(BEST == "scalar", reason="this processor has no SIMD path")


@pytest.fixture(scope="module")
def cal():
    return seat_calibration(mat_seed=5)


@pytest.fixture(autouse=True)
def simd_back_on() -> Iterator[None]:
    yield
    _core.set_simd(True)


def same_bits(a: Any, b: Any) -> None:
    """Arrays (or tuples of arrays and numbers) equal bit for bit."""
    if isinstance(a, tuple):
        for x, y in zip(a, b, strict=True):
            same_bits(x, y)
    else:
        a, b = np.asarray(a), np.asarray(b)
        assert a.shape == b.shape and a.dtype == b.dtype
        np.testing.assert_array_equal(a.view(np.uint8), b.view(np.uint8))


def both_paths(run: Callable[[], Any]) -> tuple[Any, Any]:
    """``run()`` on the scalar kernels, then on the best SIMD path; on an AVX-512 processor
    also with the AVX2 kernels forced in between, and with the AVX-512 kernels' other
    lookup of table cells (gathers or loads per lane), each of which must give the scalar
    bits too."""
    _core.set_simd(False)
    assert _core.simd_path()[0] == "scalar"
    scalar = run()
    if BEST == "avx512":
        _core.set_simd_path("avx2")
        assert _core.simd_path()[0] == "avx2"
        same_bits(scalar, run())
        _core.set_simd(True)
        used, default = _core.simd_lookup()
        assert used == default
        _core.set_simd_lookup("gather" if default == "loads" else "loads")
        try:
            same_bits(scalar, run())
        finally:
            _core.set_simd_lookup("auto")
    _core.set_simd(True)
    assert _core.simd_path()[0] == BEST
    return scalar, run()


def test_the_path_can_be_limited():
    _core.set_simd_path("scalar")
    assert _core.simd_path()[0] == "scalar"
    _core.set_simd_path("avx512")
    assert _core.simd_path()[0] == BEST
    with pytest.raises(ValueError, match="one of scalar, avx2, avx512"):
        _core.set_simd_path("sse2")


def test_the_lookup_can_be_chosen():
    used, default = _core.simd_lookup()
    assert used == default and default in ("gather", "loads")
    for lookup in ("gather", "loads"):
        _core.set_simd_lookup(lookup)
        assert _core.simd_lookup() == (lookup, default)
    _core.set_simd_lookup("auto")
    assert _core.simd_lookup() == (default, default)
    with pytest.raises(ValueError, match="one of gather, loads, auto"):
        _core.set_simd_lookup("scatter")


def spoil(x: np.ndarray, rng: np.random.Generator, lo: float, hi: float) -> np.ndarray:
    """Readings with NaN, infinities, values beyond both ends of the range and repeats."""
    x = x.copy()
    kind = rng.integers(0, 12, x.shape)
    x[kind == 0] = np.nan
    x[kind == 1] = np.inf
    x[kind == 2] = -np.inf
    x[kind == 3] = lo - 1.0
    x[kind == 4] = hi + 1.0
    x[kind == 5] = lo
    rep = kind == 6
    rep[0] = False
    x[rep] = np.roll(x, 1, axis=0)[rep]
    return x


def test_preisach_bank_same_bits_on_both_paths(cal):
    model = cal["hysteresis"].model_
    lo, hi = model.u_min_, model.u_max_
    rng = np.random.default_rng(4)
    walk = lo + np.abs(np.cumsum(rng.normal(0, 0.05, (300, 203)), axis=0)) % (hi - lo)
    walk = spoil(walk, rng, lo, hi)
    ok = rng.random(walk.shape) > 0.05

    def run() -> tuple[np.ndarray, ...]:
        bank = model.bank(walk.shape[1])
        out = bank.run(walk, ok, schedule="blocks")
        bank.reset()
        given = np.full(walk.shape, 7.0)  # the same batch into an array given as `out`
        assert bank.run(walk, ok, schedule="frames", out=given) is given
        return out, given, bank.clamped(), bank.depth(), bank.outputs()

    scalar, simd = both_paths(run)
    assert np.isnan(scalar[0]).any() and np.isfinite(scalar[0]).mean() > 0.5
    np.testing.assert_array_equal(scalar[0].view(np.uint64), scalar[1].view(np.uint64))
    for a, b in zip(scalar, simd, strict=True):
        np.testing.assert_array_equal(a.view(np.uint64), b.view(np.uint64))


def test_float32_bank_same_bits_on_both_paths_and_close_to_float64(cal):
    # the experimental float32 bank (eight lanes): its lanes give its scalar kernel's bits,
    # and the seat model's outputs stay within 1e-5 |p| + 2e-5 N/cm² of the float64 bank's
    # (the microcontroller's float32 bound, docs/embedded.md)
    model = cal["hysteresis"].model_
    lo, hi = model.u_min_, model.u_max_
    table = np.ascontiguousarray(model.everett_, dtype=np.float64)
    rng = np.random.default_rng(5)
    walk = lo + np.abs(np.cumsum(rng.normal(0, 0.05, (300, 203)), axis=0)) % (hi - lo)
    ok = rng.random(walk.shape) > 0.05
    spoilt = spoil(walk, rng, lo, hi)

    def run() -> tuple[np.ndarray, ...]:
        bank = _core.PreisachBank32(lo, hi, table, walk.shape[1], model.offset_, model.sign_)
        clean = bank.run(walk, ok)
        bank.reset()
        given = np.full(walk.shape, 7.0)
        assert bank.run(spoilt, ok, out=given) is given
        return clean, given

    scalar, simd = both_paths(run)
    for a, b in zip(scalar, simd, strict=True):
        np.testing.assert_array_equal(a.view(np.uint64), b.view(np.uint64))
    y64 = model.bank(walk.shape[1]).run(walk, ok)
    assert np.array_equal(np.isnan(y64), np.isnan(simd[0]))
    assert np.nanmax(np.abs(simd[0] - y64) - 1e-5 * np.abs(y64)) <= 2e-5
    assert np.isnan(simd[1]).any() and np.isfinite(simd[1]).mean() > 0.5


def test_float32_drift_same_bits_on_both_paths_and_close_to_float64():
    # the experimental float32 drift bank (eq. 5.8, time clock): its lanes give its scalar
    # kernel's bits; on 500 frames its outputs stay within 1e-4 N/cm² of the float64 bank's
    rng = np.random.default_rng(6)
    w, taus = rng.random(14), 2.0 ** np.arange(14)
    h = np.clip(2 + np.cumsum(rng.normal(0, 0.2, (500, 203)), axis=0), 0, 10)
    h[rng.random(h.shape) < 0.03] = np.nan
    ok = rng.random(h.shape) > 0.05
    dt = np.full(500, 0.1)

    def run() -> np.ndarray:
        return _core.DriftBank32(w, taus, -0.025, h.shape[1]).run(dt, h, ok)

    scalar, simd = both_paths(run)
    np.testing.assert_array_equal(scalar.view(np.uint64), simd.view(np.uint64))
    y64 = _core.DriftBank(w, taus, -0.025, h.shape[1]).run(dt, h, ok)
    assert np.array_equal(np.isnan(y64), np.isnan(simd))
    assert np.nanmax(np.abs(simd - y64)) < 1e-4


def test_preisach_out_must_be_a_separate_float64_array_of_the_batch(cal):
    bank = cal["hysteresis"].model_.bank(6)
    walk = np.full((4, 6), 0.5)
    ok = np.ones(walk.shape, bool)
    frozen = np.zeros((4, 6))
    frozen.flags.writeable = False
    for bad, why in (
        (frozen, "cannot write into"),
        (np.empty((4, 5)), r"shape \[4, 5\]"),
        (np.empty((4, 12))[:, ::2], "C-contiguous"),
        (np.empty((4, 6), np.float32), "float64"),
        (walk, "cannot write into"),
    ):
        with pytest.raises((ValueError, TypeError, RuntimeError), match=why):
            bank.run(walk, ok, out=bad)


def test_pipeline_same_bits_on_both_paths_in_batches_and_steps(cal):
    conv = cal["convert"]
    lay = Layout.grid(12, 17, pitch_cm=1.0)  # 204 elements: blocks not a multiple of 4
    n = lay.n_elements
    rng = np.random.default_rng(9)
    chain = StageChain([
        Convert(3.0).set_fitted(
            curve_compression_mm=conv.curve_compression_mm_,
            curve_capacitance_pF=conv.curve_capacitance_pF_,
            offset_pF=rng.normal(0, 0.05, n), gain=rng.normal(1, 0.03, n),
        ),
        *cal.without("detect", "convert").stages,
    ])  # fmt: skip
    t = np.arange(120) * 0.05
    e = 1.1 + 0.9 * np.sin(t[:, None] / 2 + np.arange(lay.n_elements)[None, :] / 9)
    e += rng.normal(0, 0.05, e.shape)
    cap = np.interp(e, conv.curve_compression_mm_, conv.curve_capacitance_pF_)
    cap = spoil(cap, rng, 0.0, float(conv.curve_capacitance_pF_[-1]))
    valid = rng.random(cap.shape) > 0.03

    def run() -> tuple[np.ndarray, ...]:
        pipe = Pipeline(chain, lay, repair="neighbour-mean")
        batch = pipe.process(cap, t, valid)
        stream = Pipeline(chain, lay, repair="neighbour-mean")
        steps = [stream.step(cap[k], valid[k], t[k])[0] for k in range(40)]
        return (*batch, np.array(steps))

    scalar, simd = both_paths(run)
    values = scalar[0]
    assert np.isfinite(values).mean() > 0.5 and (~scalar[1]).any()
    for a, b in zip(scalar, simd, strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    np.testing.assert_array_equal(values.view(np.uint64), simd[0].view(np.uint64))
