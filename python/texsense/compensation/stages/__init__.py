"""Stages as peers: one contract (:mod:`texsense.compensation.stage`) for every stage of the
capacitance-to-pressure chain, and the chain of a mat's stages, its one calibration.

=============  ================================  =========================================
stage          maps                              learns in ``fit``
=============  ================================  =========================================
``detect``     capacitance -> capacitance,       unloaded level and largest expected
               validity &= healthy (§6.5.2.5)    reading per element
               (:class:`~texsense.compensation.health.FailureDetector`)
``convert``    capacitance -> compression        material curve, per-element offset and
               (eq. 2.1)                         gain (zeroing, equilibration)
``linear``     reading -> value, offset and      offset and gain per element (given)
               gain per element
``hysteresis`` compression -> pressure           the Everett function
               (eq. 4.15-4.22)
``drift``      pressure -> pressure (eq. 5.8)    γ and the kernel, from held steps
``repair``     fills failed readings (eq. 6.14   nothing (parameters only)
               and better methods,
               :class:`~texsense.compensation.repair.Repair`)
=============  ================================  =========================================

:class:`StageChain` holds the fitted stages of a mat in order and saves them as one file
(``texsense.chain``, :mod:`texsense.data.modelfile`); :func:`load_chain` reads it and every
earlier calibration format (:mod:`texsense.data.legacy`). ``Pipeline(chain, layout)`` runs the
whole chain as one pass of the Rust core, with the same numbers as ``chain.run``.

Examples
--------
>>> import numpy as np
>>> from texsense import Layout
>>> from texsense.compensation.stages import Repair
>>> stage = Repair(Layout.grid(3, 3), method="neighbour-mean").fit()
>>> x = np.arange(9.0); ok = np.ones(9, bool); ok[4] = False
>>> values, valid = stage.step(x, ok, t=0.0)
>>> float(values[4]), bool(valid[4])
(4.0, False)
"""

import importlib
import pkgutil

from texsense.compensation.health import FailureDetector
from texsense.compensation.repair import Repair
from texsense.compensation.stage import Stage
from texsense.compensation.stages.chain import (
    STAGES,
    StageChain,
    chain_from_dict,
    load_chain,
    load_stage,
    stage_from_dict,
)
from texsense.compensation.stages.convert import Convert, Linear
from texsense.compensation.stages.spacer import Drift, Hysteresis


def _load_stages() -> None:
    """Import every public module of this folder: a stage defined there registers itself
    (:data:`STAGES`), so a new stage is one module here plus its tests."""
    for info in pkgutil.iter_modules(__path__):
        if not info.name.startswith("_"):
            importlib.import_module(f"{__name__}.{info.name}")


_load_stages()


def ranges_table() -> str:
    """Every stage's declared parameter ranges (``Stage.ranges``) as a Markdown table, as
    docs/pipeline.md lists them."""
    rows = ["| stage | parameter | range |", "|---|---|---|"]
    for name in sorted(STAGES):
        for key, kind in STAGES[name].ranges.items():
            rows.append(f"| `{name}` | `{key}` | {kind.text()} |")
    return "\n".join(rows)


__all__ = [
    "STAGES",
    "Convert",
    "Drift",
    "FailureDetector",
    "Hysteresis",
    "Linear",
    "Repair",
    "Stage",
    "StageChain",
    "chain_from_dict",
    "load_chain",
    "load_stage",
    "ranges_table",
    "stage_from_dict",
]
