"""Posture classification from pressure maps (thesis chapter 6): features, classifiers,
leave-one-subject-out evaluation, forward selection, class distances, trained models and
the error-modelling study.
"""

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
