"""A report of one recording for a clinician's file or a paper's supplement: ``texsense report
RECORDING -o report.pdf`` (or ``.html``), and the **report** button of the dashboard
(docs/report.md).

What it holds, from :func:`texsense.apps.review.open_review`:

1. the recording's identity (file, source, device, calibration id, units, start and span,
   mode and settings) and a summary;
2. the peak and mean maps on the mode's fixed colour scale, the threshold on the colour bar
   and as a contour on the maps, the map's orientation at its edges;
3. load, peak pressure, contact area and centre of force over time, with the alerts marked;
4. statistics per region (the regions of interest saved with the recording, the layout's
   named regions, the seat's zones or, on a bed, the at-risk regions of each side found on
   that side's mean map): elements, mean, peak, time above the threshold;
5. the events and alerts with their times and places;
6. sensor health (elements invalid in some frames, silent elements) on a map, and for a bed
   the time per side and the turns.

The PDF is made with matplotlib (several A4 pages, fonts embedded as TrueType so that the
tables are text a reader can select and copy) and written through
:func:`texsense.data.files.atomic_path`; the HTML is one self-contained file (tables as HTML
tables, figures as embedded PNG) written with :func:`texsense.data.files.write_text`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from texsense.apps.report._content import report_content
from texsense.apps.report._html import write_html
from texsense.apps.report._pdf import write_pdf
from texsense.apps.review import open_review
from texsense.apps.roi import load_rois
from texsense.data.files import check_not_input
from texsense.data.recording import Recording
from texsense.exceptions import ParameterError

__all__ = ["FORMATS", "write_report"]

#: Output formats by file suffix.
FORMATS = {".pdf": "pdf", ".html": "html", ".htm": "html"}


def write_report(
    source: str | Path | Recording,
    out: str | Path,
    *,
    rois: list[dict[str, Any]] | None = None,
    **options: Any,
) -> Path:
    """Write the report of ``source`` (a path texsense reads, or a Recording) to ``out``
    (``.pdf`` or ``.html``); returns the path.

    ``rois``: regions of interest (:mod:`texsense.apps.roi`; default: the sidecar saved beside a
    recording file). ``options`` go to :func:`texsense.apps.review.open_review` (``mode``,
    ``unit``, ``scale``, ``threshold_mmhg``, ``reposition_min``, ``turn_every_min``,
    ``model``, ``name``).
    """
    out = Path(out)
    fmt = FORMATS.get(out.suffix.lower())
    if fmt is None:
        raise ParameterError(f"{out.name}: a report is .pdf or .html")
    if not isinstance(source, Recording):
        check_not_input(out, [source], what="report")
        if rois is None:
            rois = load_rois(source)
    review = open_review(source, **options)
    content = report_content(review, rois or [])
    if fmt == "pdf":
        return write_pdf(content, out)

    return write_html(content, out)
