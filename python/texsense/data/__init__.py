"""The data model and its files: what a pressure map is and how it is kept.

- :mod:`~texsense.data.units`: quantities and units (pressure in N/cm² inside);
- :mod:`~texsense.data.layout`: where each element is, its neighbours, regions, orientation;
- :mod:`~texsense.data.recording`: frames + times + layout + validity + labels + metadata;
- :mod:`~texsense.data.files`: the one way a file is written (temporary name, then renamed);
- :mod:`~texsense.data.modelfile` and :mod:`~texsense.data.legacy`: the envelope of every
  model file and the reader of earlier formats.

The file formats themselves are :mod:`texsense.io` (readers, writers, the device protocol),
in the same layer. Layer rule: these modules import only :mod:`texsense.exceptions`,
:mod:`texsense._core` and each other (checked by tests/test_imports.py).
"""
