"""The import paths of before the layered tree (issue 35), kept for one release.

``import texsense.bed`` (or ``from texsense.stages import StageChain``) still works: it warns
with a :class:`DeprecationWarning` naming the new path and gives the very module of the new
path (one module object, so classes and ``isinstance`` are the same under both names). The
finder below is the only place that knows the old names; it goes in the next release.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
import warnings
from types import ModuleType

#: Old module or package -> its new place (a package's submodules follow it).
MOVED = {
    "texsense.recording": "texsense.data.recording",
    "texsense.layout": "texsense.data.layout",
    "texsense.units": "texsense.data.units",
    "texsense.files": "texsense.data.files",
    "texsense.modelfile": "texsense.data.modelfile",
    "texsense.legacy": "texsense.data.legacy",
    "texsense.monitor.protocol": "texsense.data.protocol",
    "texsense.stage": "texsense.compensation.stage",
    "texsense.testing": "texsense.compensation.testing",
    "texsense.health": "texsense.compensation.health",
    "texsense.repair": "texsense.compensation.repair",
    "texsense.drift": "texsense.compensation.drift",
    "texsense.drift_structure": "texsense.compensation.drift_structure",
    "texsense.pipeline": "texsense.compensation.pipeline",
    "texsense.archive": "texsense.compensation.archive",
    "texsense.hysteresis": "texsense.compensation.hysteresis",
    "texsense.stages": "texsense.compensation.stages",
    "texsense.sim.readout": "texsense.sensor.readout",
    "texsense.calibration_session": "texsense.calibration.session",
    "texsense.calibration_checks": "texsense.calibration.checks",
    "texsense.workflows": "texsense.calibration.workflows",
    "texsense.bed": "texsense.apps.bed",
    "texsense.stocking": "texsense.apps.stocking",
    "texsense.muscle": "texsense.apps.muscle",
    "texsense.stats": "texsense.apps.stats",
    "texsense.views": "texsense.apps.views",
    "texsense.roi": "texsense.apps.roi",
    "texsense.plotting": "texsense.apps.plotting",
    "texsense.review": "texsense.apps.review",
    "texsense.review_events": "texsense.apps.review_events",
    "texsense.monitor.alerts": "texsense.apps.alerts",
    "texsense.posture": "texsense.apps.posture",
    "texsense.report": "texsense.apps.report",
    "texsense.tables": "texsense.commands._tables",
}


def new_name(old: str) -> str | None:
    """The present name of a module imported by its old name, or None if it did not move."""
    for prefix, target in MOVED.items():
        if old == prefix or old.startswith(prefix + "."):
            return target + old[len(prefix) :]
    return None


class _Alias(importlib.abc.Loader):
    """Loads an old name as the module of its new name."""

    def __init__(self, new: str) -> None:
        self.new = new
        self.spec: importlib.machinery.ModuleSpec | None = None

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        module = importlib.import_module(self.new)
        self.spec = module.__spec__  # the import system sets the alias's spec; restored below
        return module

    def exec_module(self, module: ModuleType) -> None:
        module.__spec__ = self.spec


class _OldPaths(importlib.abc.MetaPathFinder):
    """Finds the old names (and only those) before the path finder does."""

    def find_spec(
        self, fullname: str, path: object = None, target: object = None
    ) -> importlib.machinery.ModuleSpec | None:
        new = new_name(fullname)
        if new is None:
            return None
        warnings.warn(
            f"{fullname} moved to {new}; the old name goes in the next release",
            DeprecationWarning,
            stacklevel=2,
        )
        return importlib.util.spec_from_loader(fullname, _Alias(new))


def install() -> None:
    """Put the finder of old names first on ``sys.meta_path`` (once)."""
    if not any(isinstance(f, _OldPaths) for f in sys.meta_path):
        sys.meta_path.insert(0, _OldPaths())
