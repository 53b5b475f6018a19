"""The contract of every stateful stage of texsense (the stages of a calibration, the failure
detector, the repairs, the chain and the compiled pipeline): one way to build, fit, stream,
run and save them.

- **parameters** are the constructor's arguments, stored under the same names and read back
  from its signature (:meth:`Stage.get_params`, as scikit-learn does); nothing is learned in
  the constructor;
- **fit** learns and returns the stage; everything learned ends in ``_``
  (:meth:`Stage.set_fitted` sets it from numbers, the same path a file takes);
- **streaming and batch**: ``step(values, valid, t)`` for one frame (values and validity of
  N elements at time ``t`` in s, all three required) and ``run(recording)`` for many return
  values and validity the same way, the same numbers either way; ``reset()`` forgets the
  stream. A reading that is invalid or not a number leaves that element's state untouched
  (only time passes for it) and is marked invalid in the output;
- **files**: ``to_dict``/``save`` and :func:`texsense.compensation.stages.load_stage` use the one
  model file envelope (:mod:`texsense.data.modelfile`).

Subclasses implement ``_block(values, valid, dt)`` on (T, N) float64 arrays with the time
steps (T,) of the frames, ``_prepare()`` (build the kernels from the learned state) and
``_reset_stream()``, and the JSON of their learned state.
:func:`texsense.compensation.testing.check_stage` checks the contract for any stage.
"""

from __future__ import annotations

import functools
import inspect
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar, Self

import numpy as np
import numpy.typing as npt

from texsense.data.modelfile import Fields, load, write
from texsense.data.ranges import Checked, Kind, RangeError, check_params
from texsense.data.recording import Recording
from texsense.exceptions import FormatError, NotFittedError, ParameterError

__all__ = ["STAGES", "Stage", "Stream", "time_steps"]


def time_steps(times: npt.ArrayLike, last_t: float | None = None) -> np.ndarray:
    """Time steps (s) of frames at ``times`` (T,) after a frame at ``last_t`` (None: the
    first frame has step 0); times must be finite and must not decrease."""
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    if t.size == 0:
        return t
    dt = np.diff(t, prepend=t[0] if last_t is None else last_t)
    if not np.all(np.isfinite(dt)) or np.any(dt < 0):
        raise ParameterError("frame times must be numbers and must not decrease")
    return np.ascontiguousarray(dt)


#: the plain types a stage's parameter may have in a model file, by its type hint's name
_PLAIN = {"float": (int, float), "int": (int, float), "str": (str,), "bool": (bool,)}


def _plain_param(value: Any, hint: Any) -> Any:
    """A parameter of a model file checked against its type hint (``float``, ``int``, ``str``,
    ``bool``, each possibly ``| None``): a text where a number belongs, a number of 1e308
    where a count belongs or an object anywhere is a ``TypeError``/``ValueError`` that
    :meth:`Stage.from_dict` names, not a traceback from deep in a kernel. Other hints (a
    ``Layout``) are decoded by their own ``from_dict``."""
    names = [a.__name__ for a in typing.get_args(hint)] if typing.get_args(hint) else []
    names = names or [getattr(hint, "__name__", "")]
    if value is None and "NoneType" in names:
        return None
    kinds = [n for n in names if n in _PLAIN]
    if not kinds:
        return value
    kind = kinds[0]
    if isinstance(value, bool) != (kind == "bool") or not isinstance(value, _PLAIN[kind]):
        raise TypeError(f"expected {'a number' if kind in ('int', 'float') else kind}, "
                        f"got {type(value).__name__}")  # fmt: skip
    if kind == "int":
        number = typing.cast(float, value)  # an int or a float here (checked above)
        if number != number or abs(number) > 2**62 or number != int(number):
            raise ValueError(f"expected a whole number, got {value}")
        return int(value)
    return value


class Stream:
    """Streaming and batch over one checked batch path, ``_arrays(values, valid, times)``:
    what every stage and the chain of stages share."""

    @property
    def reads(self) -> tuple[str, str]:
        """(quantity, unit) read ("": any)."""
        raise NotImplementedError

    @property
    def gives(self) -> tuple[str, str]:
        """(quantity, unit) given ("": what is read)."""
        raise NotImplementedError

    def _what(self) -> str:
        raise NotImplementedError

    def _arrays(
        self, values: npt.ArrayLike, valid: npt.ArrayLike | None, times: npt.ArrayLike
    ) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def step(
        self, values: npt.ArrayLike, valid: npt.ArrayLike | None, t: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """One frame: values (N,), validity (N,) (None: all valid) at time ``t`` (s) ->
        values and validity (N,)."""
        x = np.asarray(values, dtype=np.float64).reshape(1, -1)
        ok = None if valid is None else np.asarray(valid, dtype=bool).reshape(1, -1)
        out, out_ok = self._arrays(x, ok, [float(t)])
        return out[0], out_ok[0]

    def run(self, rec: Recording) -> Recording:
        """A recording of what is read -> a recording of what is given, with the validity of
        every reading; continues the stream."""
        quantity, unit = self.reads
        if quantity and rec.quantity != quantity:
            raise ParameterError(f"{self._what()} reads {quantity}, not {rec.quantity}")
        frames = rec.to_unit(unit).frames if unit and rec.unit != unit else rec.frames
        out, ok = self._arrays(frames, rec.valid, rec.times)
        gives_q, gives_u = self.gives
        return rec._with(
            frames=out, valid=ok, quantity=gives_q or rec.quantity, unit=gives_u or rec.unit
        )


#: Every stage class by its name in files and chains (a subclass of :class:`Stage` that sets
#: ``name`` registers itself here; :mod:`texsense.compensation.stages` loads them all).
STAGES: dict[str, type[Stage]] = {}


class Stage(Stream, Checked):
    """The contract (see the module documentation). A subclass that sets ``name`` is a stage
    of the registry :data:`STAGES`: model files, chains and the stage contract test find it
    there."""

    #: Name in files and in a chain.
    name: ClassVar[str] = ""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        name = cls.__dict__.get("name")
        if name:
            other = STAGES.get(name)
            if other is not None and other.__qualname__ != cls.__qualname__:
                raise TypeError(f"{cls.__name__}: the stage name {name!r} is {other.__name__}'s")
            STAGES[name] = cls
        init = cls.__dict__.get("__init__")
        if init is not None:  # every constructor ends with the check of the parameters

            @functools.wraps(init)
            def checked(self: Stage, *args: Any, **kw: Any) -> None:
                init(self, *args, **kw)
                if type(self).__init__ is checked:  # the outermost constructor only
                    self.check_all()  # and each parameter set after (ranges.Checked)

            setattr(cls, "__init__", checked)  # noqa: B010 (mypy: no assigning to a method)

    #: The kind and range of every parameter (:mod:`texsense.data.ranges`), declared next to
    #: the constructor: the constructor checks them (:meth:`check_params`), whether the stage
    #: is made from Python keywords, a command's options or a model file.
    ranges: ClassVar[Mapping[str, Kind]] = {}

    #: (quantity, unit) read and given; "" passes what comes.
    _reads: ClassVar[tuple[str, str]] = ("", "")
    _gives: ClassVar[tuple[str, str]] = ("", "")

    _last_t: float | None = None

    @property
    def reads(self) -> tuple[str, str]:
        """(quantity, unit) the stage reads ("" : any)."""
        return self._reads

    @property
    def gives(self) -> tuple[str, str]:
        """(quantity, unit) the stage gives ("": what it reads)."""
        return self._gives

    # ------------------------------------------------------------------ parameters
    @classmethod
    def _param_names(cls) -> list[str]:
        sig = inspect.signature(cls.__init__)
        return [
            p.name
            for p in sig.parameters.values()
            if p.name != "self" and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
        ]

    def check_params(self) -> None:
        """Check every parameter against the declared :attr:`ranges`: one
        :class:`~texsense.data.ranges.RangeError` naming the stage, the parameter, the value
        and the range."""
        check_params(self._what(), type(self).ranges, self.get_params())

    def _params(self) -> dict[str, Any]:
        return self.get_params()

    def get_params(self) -> dict[str, Any]:
        """The constructor's arguments, by name (``type(s)(**s.get_params())`` is the same
        stage unfitted)."""
        return {name: getattr(self, name) for name in self._param_names()}

    # ------------------------------------------------------------------ learned state
    def is_fitted(self) -> bool:
        """True once the stage has learned its state (fit, set_fitted or a file)."""
        return any(k.endswith("_") and not k.startswith("_") for k in vars(self))

    def _check_fitted(self) -> None:
        if not self.is_fitted():
            raise NotFittedError(f"the {self.name} stage is not fitted yet: call fit()")

    def set_fitted(self, **learned: Any) -> Self:
        """Give the stage learned state from numbers (``name=value`` for each ``name_``),
        checked as a file's is; returns the stage, its stream reset."""
        for key, value in learned.items():
            setattr(self, f"{key}_", value)
        self._prepare()
        return self.reset()

    def _prepare(self) -> None:
        """Check the learned state and build what runs it (the kernels)."""

    # ------------------------------------------------------------------ the stream
    def reset(self) -> Self:
        """Forget the stream (the start of a new recording); the learned state stays."""
        self._last_t = None
        if self.is_fitted():
            self._reset_stream()
        return self

    def _reset_stream(self) -> None:
        """Forget the stream state of the kernels."""

    def _what(self) -> str:
        return f"the {self.name} stage"

    def _block(
        self, values: np.ndarray, valid: np.ndarray, dt: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(T, N) values and validity with the time steps (T,) -> the same, continuing the
        stream."""
        raise NotImplementedError

    def _arrays(
        self, values: npt.ArrayLike, valid: npt.ArrayLike | None, times: npt.ArrayLike
    ) -> tuple[np.ndarray, np.ndarray]:
        """The checked batch path that ``step``, ``run`` and a chain share."""
        self._check_fitted()
        x = np.ascontiguousarray(values, dtype=np.float64)
        if x.ndim != 2:
            raise ParameterError(f"expected frames (T, N), got shape {x.shape}")
        ok = np.ones(x.shape, bool) if valid is None else np.asarray(valid, dtype=bool)
        if ok.shape != x.shape:
            raise ParameterError(f"valid has shape {ok.shape}, values {x.shape}")
        ok = np.ascontiguousarray(ok & np.isfinite(x))
        if x.shape[0] == 0:
            return x, ok
        dt = time_steps(times, self._last_t)
        if dt.shape != (x.shape[0],):
            raise ParameterError(f"expected {x.shape[0]} frame times, got {dt.size}")
        out, out_ok = self._block(x, ok, dt)
        self._last_t = float(np.asarray(times, dtype=np.float64).reshape(-1)[-1])
        return out, out_ok

    # ------------------------------------------------------------------ files
    def _fitted_json(self) -> dict[str, Any]:
        """The learned state as JSON."""
        raise NotImplementedError

    @classmethod
    def _fitted_from_json(cls, fields: Fields, params: Mapping[str, Any]) -> dict[str, Any]:
        """The learned state (for :meth:`set_fitted`) from a file's fields."""
        raise NotImplementedError

    def to_dict(self) -> dict[str, Any]:
        """The content of the stage in a model file: name, parameters, learned state."""
        params = {
            k: v.to_dict() if hasattr(v, "to_dict") else v for k, v in self.get_params().items()
        }
        return {
            "stage": self.name,
            "params": params,
            "fitted": self._fitted_json() if self.is_fitted() else None,
        }

    @classmethod
    def from_dict(cls, content: Mapping[str, Any], source: str | Path = "<dict>") -> Self:
        """A stage of this class from its content (see
        :func:`texsense.compensation.stages.stage_from_dict` for any stage)."""
        f = Fields(content, source)
        params = f.get("params", {})
        if not isinstance(params, dict):
            raise f.error("params", "expected an object")
        hints = typing.get_type_hints(cls.__init__)
        known = set(cls._param_names())
        unknown = set(params) - known
        if unknown:
            raise f.error("params", f"unknown parameters {sorted(unknown)} of {cls.name}")
        args = {}
        for key, value in params.items():
            decode = getattr(hints.get(key), "from_dict", None)
            try:
                if decode is not None and value is not None:
                    args[key] = decode(value)
                else:
                    args[key] = _plain_param(value, hints.get(key))
            except (KeyError, TypeError, ValueError, OverflowError) as e:
                raise f.error(f"params.{key}", f"cannot be read ({e})") from None
        try:
            stage = cls(**args)
        except RangeError as e:
            raise f.error(f"params.{e.key}", str(e)) from None
        except (TypeError, ValueError) as e:
            raise f.error("params", str(e)) from None
        if content.get("fitted") is not None:
            try:
                fitted = cls._fitted_from_json(f.sub("fitted"), args)
                stage.set_fitted(**fitted)
            except FormatError:
                raise  # names its field already
            except (ParameterError, ValueError) as e:
                raise f.error("fitted", str(e)) from None
        return stage.reset()

    def save(self, path: str | Path) -> Path:
        """Write the stage as a model file (``texsense.compensation.stage``), atomically."""
        return write(path, "texsense.stage", self.to_dict())

    @classmethod
    def load(cls, path: str | Path) -> Self:
        """Read a stage file of this stage (of this version or an earlier one)."""
        _, content = load(path, ("texsense.stage",))
        if content.get("stage") != cls.name:
            raise FormatError(path, f"holds the {content.get('stage')!r} stage, not {cls.name}")
        return cls.from_dict(content, path)

    def __getstate__(self) -> dict[str, Any]:
        """Parameters and learned state (pickle, deepcopy); the kernels and the stream are
        rebuilt on the other side, which starts a new stream."""
        return {k: v for k, v in vars(self).items() if not k.startswith("_")}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        if self.is_fitted():
            self._prepare()
        self.reset()

    def __repr__(self) -> str:
        state = "fitted" if self.is_fitted() else "not fitted"
        params = ", ".join(
            f"{k}={v!r}" for k, v in self.get_params().items() if not hasattr(v, "to_dict")
        )
        return f"{type(self).__name__}({params}; {state})"
