"""What people do with pressure maps: statistics, regions, views and plots, the clinical
applications (exposure and reposition alerts, beds, stockings, muscle), posture and reports.

- analysis: :mod:`~texsense.apps.stats`, :mod:`~texsense.apps.roi`,
  :mod:`~texsense.apps.views`, :mod:`~texsense.apps.plotting`;
- clinical: :mod:`~texsense.apps.alerts` (exposure, reposition), :mod:`~texsense.apps.bed`,
  :mod:`~texsense.apps.stocking`, :mod:`~texsense.apps.muscle`, :mod:`~texsense.apps.posture`;
- review: :mod:`~texsense.apps.review`, :mod:`~texsense.apps.review_events`,
  :mod:`~texsense.apps.report`.

Layer rule: imports the layers below (data, compensation, calibration, sensor, sim) and never
the live products (:mod:`texsense.monitor`, :mod:`texsense.station`) or the command line
(tests/test_imports.py).
"""
