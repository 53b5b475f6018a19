"""Every batch of the compiled core returns new numpy arrays that numpy owns (issue 34, twentieth
round: the kernels write into arrays from numpy's allocator, which asks Linux for huge pages for
large arrays, instead of Rust vectors handed over): the shape, dtype and flags a caller can rely
on, and the same values as a second run of the same batch."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from texsense import _core
from texsense.calibration.workflows import seat_calibration
from texsense.compensation.pipeline import Pipeline
from texsense.sim.mat import VirtualMat
from texsense.sim.spacer import Spacer

T = 40


@pytest.fixture(scope="module")
def cases() -> tuple[int, dict[str, Callable[[], tuple[np.ndarray, ...]]]]:
    """The elements N of the virtual seat, and name -> a batch of T x N from scratch (every
    object new, so that runs agree)."""
    rng = np.random.default_rng(3)
    cal = seat_calibration(mat_seed=5)
    lay = VirtualMat.seat(seed=5).layout
    model = cal["hysteresis"].model_
    N = lay.n_elements
    lo, hi = model.u_min_, model.u_max_
    u = lo + (hi - lo) * rng.random((T, N))
    ok = rng.random((T, N)) > 0.1
    dt = np.full(T, 0.05)
    cap = 20.0 + rng.random((T, N))
    indptr, indices = (np.asarray(a, np.int64) for a in lay.neighbours)
    w, taus = np.array([0.3, 0.2]), np.array([1.0, 30.0])
    table = np.ascontiguousarray(model.everett_, dtype=np.float64)

    def detector() -> _core.FailureDetector:
        jump = np.full(N, 5.0)
        return _core.FailureDetector(
            indptr, indices, jump, None, None, 0.5, 0.3, 3.0, 10, 0.01, 0.1
        )

    def spacer() -> _core.SpacerBank:
        return Spacer.preset("textile-6mm", N)._new_bank()

    def pipeline() -> Pipeline:
        return Pipeline(cal, lay, repair="neighbour-mean")

    return N, {
        "PreisachBank.run": lambda: (model.bank(N).run(u, ok),),
        "PreisachBank32.run": lambda: (
            _core.PreisachBank32(model.u_min_, model.u_max_, table, N).run(u, ok),
        ),
        "Compensation.run": lambda: (
            _core.Compensation(model.bank(N), _core.DriftBank(w, taus, -0.02, N)).run(dt, u, ok),
        ),
        "FailureDetector.run": lambda: (detector().run(cap, ok),),
        "HysteresisModel.predict": lambda: (model.predict(u),),
        "DriftBank.run": lambda: (_core.DriftBank(w, taus, -0.02, N).run(dt, u, ok),),
        "DriftBank32.run": lambda: (_core.DriftBank32(w, taus, -0.02, N).run(dt, u, ok),),
        "Converter.run": lambda: (_core.Converter(np.full(N, 20.0), np.ones(N)).run(cap, ok),),
        "LocalRepair.run": lambda: _core.LocalRepair("neighbour-mean", N, indptr, indices).run(
            u, ok
        ),
        "Chain.run": lambda: pipeline().compiled().run(dt, cap, ok),
        "Chain.run_f32": lambda: pipeline().compiled().run_f32(dt, cap.astype(np.float32), ok),
        "SpacerBank.run_displacement": lambda: spacer().run_displacement(dt, 0.3 * u / hi),
        "SpacerBank.run_pressure": lambda: spacer().run_pressure(dt, 2.0 * u / hi),
    }


NAMES = [
    "PreisachBank.run",
    "PreisachBank32.run",
    "Compensation.run",
    "FailureDetector.run",
    "HysteresisModel.predict",
    "DriftBank.run",
    "DriftBank32.run",
    "Converter.run",
    "LocalRepair.run",
    "Chain.run",
    "Chain.run_f32",
    "SpacerBank.run_displacement",
    "SpacerBank.run_pressure",
]


@pytest.mark.parametrize("name", NAMES)
def test_a_batch_gives_new_arrays_numpy_owns(cases, name):
    n, batches = cases
    first = batches[name]()
    for a in first:
        assert a.shape == (T, n)
        assert a.dtype in (np.float64, np.float32, np.uint8)
        assert a.flags.c_contiguous and a.flags.writeable
        assert a.flags.owndata, f"{name}: an array numpy does not own"
        assert a.base is None
    # a second object of the same kind gives the same numbers (nothing read from a
    # previous output's memory)
    again = batches[name]()
    for a, b in zip(first, again, strict=True):
        np.testing.assert_array_equal(a, b)


def test_the_table_covers_every_batch_method_of_the_core():
    """Every `run*` method of every class of the core is in the table (a new one must be
    added there)."""
    batch = {
        f"{name}.{m}"
        for name in dir(_core)
        if isinstance(getattr(_core, name), type)
        for m in dir(getattr(_core, name))
        if m.startswith("run")
    }
    assert batch == set(NAMES) - {"HysteresisModel.predict"}, sorted(batch ^ set(NAMES))
