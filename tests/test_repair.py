import numpy as np
import pytest

from texsense import Layout, Recording
from texsense.compensation.repair import Repair
from texsense.exceptions import NeighbourIndexError, ParameterError, ShapeError


def test_eq_6_14_on_a_checkerboard():
    rr, cc = np.mgrid[0:5, 0:5]
    lay = Layout.grid(5, 5, active=(rr + cc) % 2 == 0)
    frame = np.arange(lay.n_elements, dtype=float) ** 2
    valid = np.ones(lay.n_elements, bool)
    centre = lay.element_at(2, 2)
    valid[centre] = False
    valid[lay.element_at(0, 2)] = False  # one of the four is failed too: n_a = 3
    out, measured = Repair(lay, "neighbour-mean").fit().step(frame, valid, t=0.0)
    available = [lay.element_at(2, 0), lay.element_at(2, 4), lay.element_at(4, 2)]
    assert out[centre] == frame[available].mean()
    assert measured.tolist() == valid.tolist()


def test_run_equals_step_and_marks_repaired():
    rng = np.random.default_rng(0)
    lay = Layout.grid(6, 7)
    frames = rng.random((30, lay.n_elements)).astype(np.float32).astype(np.float64)
    valid = rng.random(frames.shape) > 0.4
    rec = Recording(frames, np.arange(30.0), lay, valid=valid)
    batch = Repair(lay, "neighbour-mean").fit().run(rec)
    stream = Repair(lay, "neighbour-mean").fit()
    for t in range(30):
        out, measured = stream.step(frames[t], valid[t], t=float(t))
        np.testing.assert_array_equal(out.astype(np.float32), batch.frames[t])
        np.testing.assert_array_equal(measured, batch.valid[t])
    np.testing.assert_array_equal(batch.frames[valid], frames[valid])


def test_all_neighbours_failed_takes_last_value():
    lay = Layout.grid(1, 3)
    rep = Repair(lay, "neighbour-mean").fit()
    rep.step([1.0, 2.0, 3.0], [True, True, True], t=0.0)
    out, _ = rep.step([0.0, 0.0, 0.0], [False, False, False], t=1.0)
    np.testing.assert_array_equal(out, [1.0, 2.0, 3.0])
    assert rep.outcome_.tolist() == [[2, 2, 2]]
    rep.reset()
    out, _ = rep.step([0.0, 0.0, 0.0], [False, False, False], t=0.0)
    assert np.isnan(out).all() and rep.outcome_.tolist() == [[3, 3, 3]]


def test_core_errors_map_to_python_exceptions():
    from texsense._core import LocalRepair as Core

    with pytest.raises(NeighbourIndexError, match="out of range"):
        Core("neighbour-mean", 1, np.array([0, 1]), np.array([5]))
    core = Core("neighbour-mean", 2, np.array([0, 0, 0]), np.array([], dtype=np.int64))
    with pytest.raises(ShapeError, match="2 elements per frame"):
        core.run(np.zeros((1, 3)), np.ones((1, 3), bool))
    with pytest.raises(ShapeError):
        Repair(Layout.grid(2, 2), "neighbour-mean").fit().step(np.zeros(3), None, t=0.0)
    with pytest.raises(ParameterError, match="must not decrease"):
        Repair(Layout.grid(1, 3), "zero").fit().run(
            Recording(np.zeros((2, 3)), [1.0, 0.0], Layout.grid(1, 3))
        )
