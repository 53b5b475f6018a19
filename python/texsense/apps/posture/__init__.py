"""Posture classification from pressure maps (thesis chapter 6): features, classifiers,
leave-one-subject-out evaluation, forward selection, class distances, trained models and
the error-modelling study.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from texsense.apps.posture.evaluate import (
        CLASSIFIERS,
        LosoReport,
        class_distances,
        loso,
        make_classifier,
        sequential_forward_selection,
    )
    from texsense.apps.posture.features import (
        FeatureSet,
        align_maps,
        area_means,
        centre_of_force,
        mirror_frames,
        mirror_samples,
        pool_maps,
        reduce_maps,
    )
    from texsense.apps.posture.model import PostureModel

#: Each name and its module, imported at the first use of the name (PEP 562): the classifiers
#: bring scikit-learn (seconds of import), which a module that only smooths postures
#: (texsense.apps.posture.smoothing, the monitor, ``texsense process``) does not need.
_WHERE = {
    **dict.fromkeys(
        ["CLASSIFIERS", "LosoReport", "class_distances", "loso", "make_classifier",
         "sequential_forward_selection"],
        "evaluate",
    ),
    **dict.fromkeys(
        ["FeatureSet", "align_maps", "area_means", "centre_of_force", "mirror_frames",
         "mirror_samples", "pool_maps", "reduce_maps"],
        "features",
    ),
    "PostureModel": "model",
}  # fmt: skip


def __getattr__(name: str) -> Any:
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_WHERE])


__all__ = [
    "CLASSIFIERS",
    "FeatureSet",
    "LosoReport",
    "PostureModel",
    "align_maps",
    "area_means",
    "centre_of_force",
    "class_distances",
    "loso",
    "make_classifier",
    "mirror_frames",
    "mirror_samples",
    "pool_maps",
    "reduce_maps",
    "sequential_forward_selection",
]
