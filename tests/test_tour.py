"""Every console line of the README and of docs/*.md runs as written (tests/tour.py).

In one pytest process the pages run once per session (the selected pages only), in the
background from the start of the session (tests/conftest.py, ``pytest_collection_finish``)
while the other tests run: one page at a time when other tests are selected, two at a time
otherwise. In the workers of ``pytest -n N`` (scripts/test.sh) each test runs its page itself,
side by side with the other workers' tests. Each test reports its page.
"""

import os

import pytest

from conftest import IN_WORKER, ROOT, TOUR
from tour import commands, run_page

PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
PAGES = [p for p in PAGES if commands(p)]  # the README first: the longest


@pytest.fixture(scope="session")
def outcomes(request, shared_data):
    """The background tour's outcomes by page (None in a worker of ``pytest -n``)."""
    if IN_WORKER:
        return None
    tour = request.config.stash.get(TOUR, None)
    assert tour is not None, "the tour did not start (tests/conftest.py)"
    return tour.result(timeout=1800)


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES, ids=[p.name for p in PAGES])
def test_page_runs_as_written(page, outcomes, shared_data, tmp_path, capsys):
    if outcomes is None:
        base_env = dict(os.environ, TEXSENSE_NO_PROGRESS="1")
        outcome = run_page(page, tmp_path / page.stem, shared_data.parent, base_env=base_env)
    else:
        outcome = outcomes[page]
    with capsys.disabled():
        print(f"\n  {page.name}: {len(outcome.ran)} commands in {outcome.seconds:.1f} s")
        for text, why in outcome.skipped:
            print(f"  {page.name}: skipped (needs {why}): {text}")
    assert not outcome.failures, "\n\n".join(outcome.failures)
    assert outcome.ran
