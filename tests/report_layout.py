"""A layout check of a report's rendered pages (issue 33): every page rendered with Debian's
``pdftoppm``, and on each page no blank band between two pieces of content taller than
:data:`MAX_GAP` of the page, no page but the last ending with more than :data:`MAX_TAIL` of it
blank, no page with nothing under its running header, and every word (``pdftotext -bbox``)
inside the page."""

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np

#: Tallest blank band between content, and blank tail of a page, as fractions of its height.
MAX_GAP, MAX_TAIL = 0.08, 0.4
#: The running header of a page (the report's title at the top of every page but the first).
HEADER = 0.04


def _tool(name: str) -> str:
    exe = shutil.which(name)
    assert exe is not None, f"{name} is missing: install Debian's poppler-utils"
    return exe


def blank_bands(png: Path) -> tuple[float, float]:
    """(tallest blank band between content, blank tail below the last content) of a page;
    (1, 1) for a page with nothing below its running header (the top :data:`HEADER`)."""
    import matplotlib.image as mpimg

    img = mpimg.imread(png)
    grey = img[..., :3].mean(axis=2) if img.ndim == 3 else img
    inked = np.flatnonzero((grey < 0.92).any(axis=1))
    h = grey.shape[0]
    if not (inked > HEADER * h).any():
        return 1.0, 1.0
    gaps = np.diff(inked) - 1
    return float(gaps.max(initial=0)) / h, float(h - 1 - inked[-1]) / h


def check_layout(pdf: Path, workdir: Path) -> int:
    """Assert the page layout of ``pdf`` (see the module); returns its page count."""
    stem = workdir / f"{pdf.stem}-layout"
    subprocess.run([_tool("pdftoppm"), "-r", "25", "-png", str(pdf), str(stem)], check=True)
    pages = sorted(workdir.glob(f"{stem.name}-*.png"))
    assert pages, f"{pdf}: no page rendered"
    for k, png in enumerate(pages, 1):
        gap, tail = blank_bands(png)
        assert (gap, tail) != (1.0, 1.0), f"{pdf.name} page {k}: nothing on it but its header"
        assert gap <= MAX_GAP, f"{pdf.name} page {k}: a blank band of {gap:.0%} of the page"
        if k < len(pages):
            assert tail <= MAX_TAIL, f"{pdf.name} page {k}: its last {tail:.0%} is blank"
    html = subprocess.run([_tool("pdftotext"), "-bbox", str(pdf), "-"], capture_output=True,
                          text=True, check=True).stdout  # fmt: skip
    for page in re.findall(r'<page width="([\d.]+)" height="([\d.]+)">(.*?)</page>', html, re.S):
        w, h = float(page[0]), float(page[1])
        for box in re.findall(r'xMin="([-\d.]+)" yMin="([-\d.]+)" xMax="([-\d.]+)" '
                              r'yMax="([-\d.]+)">([^<]*)<', page[2]):  # fmt: skip
            x0, y0, x1, y1 = (float(v) for v in box[:4])
            assert x0 >= 0 and x1 <= w and y0 >= 0 and y1 <= h, f"{pdf.name}: {box[4]!r} overflows"
    return len(pages)
