"""The stage contract as a check anyone who writes a stage can run (in the spirit of
scikit-learn's ``check_estimator``): :func:`check_stage` builds, fits, streams, runs, saves
and loads a stage and raises :class:`AssertionError` naming the rule it broke.

Examples
--------
>>> import numpy as np
>>> from texsense import Layout, Recording
>>> from texsense.compensation.repair import Repair
>>> lay = Layout.grid(3, 4)
>>> rng = np.random.default_rng(0)
>>> rec = Recording(rng.random((60, 12)), np.arange(60) * 0.1, lay,
...                 valid=rng.random((60, 12)) > 0.1)
>>> check_stage(Repair(lay, "neighbour-mean"), lambda s: s.fit(), rec)
"""

from __future__ import annotations

import inspect
import pickle
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from texsense.compensation.stage import Stage
from texsense.data.recording import Recording
from texsense.exceptions import NotFittedError, ParameterError

__all__ = ["check_stage"]


def _same(a: np.ndarray, b: np.ndarray, what: str, rtol: float = 0.0) -> None:
    """Equal values, NaN where the other has NaN (``rtol`` 0: to the bit)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    assert a.shape == b.shape, f"{what}: shapes {a.shape} and {b.shape}"
    nan_a, nan_b = np.isnan(a), np.isnan(b)
    assert np.array_equal(nan_a, nan_b), f"{what}: NaN in different places"
    ok = ~nan_a
    if rtol == 0.0:
        assert np.array_equal(a[ok], b[ok]), f"{what}: values differ"
    else:
        np.testing.assert_allclose(a[ok], b[ok], rtol=rtol, atol=1e-9, err_msg=what)


def _learned(stage: Stage) -> list[str]:
    return [k for k in vars(stage) if k.endswith("_") and not k.startswith("_")]


def check_parameters(stage: Stage) -> None:
    """The constructor stores its arguments under their names and learns nothing."""
    names = [p for p in inspect.signature(type(stage).__init__).parameters if p != "self"]
    params = stage.get_params()
    assert list(params) == names, f"get_params {list(params)} is not the signature {names}"
    again = type(stage)(**params)
    assert again.get_params().keys() == params.keys(), "a stage built from get_params differs"
    assert not stage.is_fitted() and not _learned(stage), "the constructor learned something"
    step = inspect.signature(type(stage).step).parameters
    assert list(step)[1:] == ["values", "valid", "t"], "step(values, valid, t)"
    assert step["t"].default is inspect.Parameter.empty, "step's t must be required"


def check_fit(stage: Stage, fit: Callable[[Stage], Stage], rec: Recording) -> Stage:
    """An unfitted stage refuses to run; fit returns the stage itself, with what it learned
    ending in ``_`` and its parameters unchanged."""
    params = stage.get_params()
    for attempt in (lambda: stage.run(rec), lambda: stage.step(rec.frames[0], None, 0.0)):
        try:
            attempt()
        except NotFittedError:
            pass
        else:
            raise AssertionError(f"the unfitted {stage.name} stage ran")
    fitted = fit(stage)
    assert fitted is stage, "fit must return the stage itself"
    assert stage.is_fitted() and _learned(stage), "what fit learns must end in _"
    assert stage.get_params().keys() == params.keys(), "fit changed the parameters"
    for k, v in params.items():
        assert stage.get_params()[k] is v, f"fit changed the parameter {k}"
    return stage


def check_streaming(stage: Stage, rec: Recording) -> None:
    """``step`` frame after frame gives what ``run`` gives, to the bit; ``reset`` replays
    the same stream; frame times must not decrease."""
    batch = stage.reset().run(rec)
    again = stage.reset().run(rec)
    _same(batch.frames, again.frames, "reset does not replay the same stream")
    stage.reset()
    rows = [
        stage.step(rec.frames[k], rec.valid[k], float(rec.times[k])) for k in range(rec.n_frames)
    ]
    values = np.array([r[0] for r in rows], dtype=np.float32)
    valid = np.array([r[1] for r in rows])
    assert np.array_equal(valid, batch.valid), "streaming and batch validity differ"
    _same(values, batch.frames, "streaming and batch values differ")
    assert not (batch.valid & ~rec.valid).any(), "an invalid reading became valid"
    try:
        stage.step(rec.frames[0], rec.valid[0], float(rec.times[-1]) - 1.0)
    except ParameterError:
        pass
    else:
        raise AssertionError("a frame earlier than the last one was accepted")


def check_invalid_readings(stage: Stage, rec: Recording, element: int) -> None:
    """An element whose readings are invalid (and not numbers) for a stretch continues
    afterwards as if those frames had not been recorded (only time passed), and those
    readings are invalid in the output."""
    n = rec.n_frames
    gap = slice(n // 3, n // 3 + max(2, n // 6))
    valid = rec.valid.copy()
    valid[gap, element] = False
    frames = rec.frames.copy()
    frames[gap, element] = np.nan
    with_gap = stage.reset().run(rec._with(frames=frames, valid=valid))
    assert not with_gap.valid[gap, element].any(), "an invalid reading came out valid"
    keep = np.ones(n, bool)
    keep[gap] = False
    without = stage.reset().run(rec.select(keep))
    after = slice(gap.stop, n)
    a, b = with_gap.valid[after, element], without.valid[gap.start :, element]
    assert np.array_equal(a, b), "the validity after the gap differs"
    _same(with_gap.frames[after, element][a], without.frames[gap.start :, element][b],
          "the element does not continue as if the invalid frames were not there",
          rtol=1e-6)  # fmt: skip


def check_files(stage: Stage, rec: Recording) -> None:
    """The stage saves and loads itself, and pickles (the same content, the same numbers)."""
    first = stage.reset().run(rec)
    copy = pickle.loads(pickle.dumps(stage))
    assert copy.to_dict() == stage.to_dict(), "the unpickled stage's content differs"
    _same(copy.run(rec).frames, first.frames, "the unpickled stage computes other numbers")
    with tempfile.TemporaryDirectory() as folder:
        path = stage.save(Path(folder) / f"{stage.name}.json")
        loaded = type(stage).load(path)
    assert type(loaded) is type(stage), "load gave another class"
    assert loaded.to_dict() == stage.to_dict(), "the loaded stage's content differs"
    _same(loaded.run(rec).frames, first.frames, "the loaded stage computes other numbers")
    d = stage.to_dict()
    assert d["stage"] == stage.name and set(d) == {"stage", "params", "fitted"}


def check_stage(
    stage: Stage, fit: Callable[[Stage], Stage], rec: Recording, *, element: int = 7
) -> None:
    """Check the stage contract (:mod:`texsense.compensation.stage`) on ``stage``.

    Parameters
    ----------
    stage : Stage
        A new, unfitted stage.
    fit : callable
        Fits the stage and returns it (e.g. ``lambda s: s.fit(data)``).
    rec : Recording
        A recording of what the stage reads, with some invalid readings, at least 12
        frames.
    element : int
        The element that fails for a stretch in the check of invalid readings.

    Raises
    ------
    AssertionError
        Naming the rule the stage broke.
    """
    assert rec.n_frames >= 12, "the check needs a recording of at least 12 frames"
    check_parameters(stage)
    check_fit(stage, fit, rec)
    check_streaming(stage, rec)
    check_invalid_readings(stage, rec, element)
    check_files(stage, rec)
