"""The posture defaults: what ``texsense posture evaluate|train`` use without options.

Chosen by a nested leave-one-subject-out comparison of 13 candidates on four data sets, PMD
(3 classes and 17 posture files), the virtual seat and the virtual bed: the best inner score
averaged over the data sets (``benchmarks/posture_defaults.py``, tables in docs/posture.md).
Mirrored training copies are used where the recording declares a mirror map (PMD does).
"""

from __future__ import annotations

from texsense.apps.posture.features import FeatureSet

__all__ = ["DEFAULT_C", "DEFAULT_CLASSIFIER", "DEFAULT_FEATURES"]

#: A linear SVM with C = 0.01 ...
DEFAULT_CLASSIFIER = "linear-svm"
DEFAULT_C: float | None = 0.01
#: ... on the maps centred on their centre of force, log-compressed and 2 x 2 pooled, plus the
#: centre of force and the 4 + 16 area means of the maps as they are (the thesis's features).
DEFAULT_FEATURES = FeatureSet(
    ("elements", "centre", "areas4", "areas16"), align=True, log=True, pool=2
)
