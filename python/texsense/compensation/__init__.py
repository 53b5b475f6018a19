"""The compensation: the stages that turn raw readings into accurate pressure, and their
identification.

- :mod:`~texsense.compensation.stage`: the stage contract (``fit``, ``step(values, valid, t)``,
  ``run``, ``save``/``load``), checked for every stage by
  :func:`~texsense.compensation.testing.check_stage`;
- :mod:`~texsense.compensation.stages`: the stages (convert, linear, hysteresis, drift) and
  the one calibration object, :class:`~texsense.compensation.stages.StageChain`;
- :mod:`~texsense.compensation.health` (detect, §6.5.2.5), :mod:`~texsense.compensation.conversion`
  (eq. 2.1), :mod:`~texsense.compensation.hysteresis` (Preisach, eq. 4.12-4.22),
  :mod:`~texsense.compensation.drift` (eq. 5.8) and :mod:`~texsense.compensation.drift_structure`,
  :mod:`~texsense.compensation.repair` (eq. 6.14);
- :mod:`~texsense.compensation.pipeline` (a chain compiled into one pass of the Rust core) and
  :mod:`~texsense.compensation.archive` (long recordings in blocks, on Dask).

Layer rule: imports the data layer (:mod:`texsense.data`, :mod:`texsense.io`) and nothing above
it; never the simulator (:mod:`texsense.sim`), which grades it (tests/test_imports.py).
"""
