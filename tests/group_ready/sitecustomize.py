"""Run at the start of every process of a test's group of stations (tests/group_cluster.py
puts this folder on their PYTHONPATH, with TEXSENSE_TEST_READY_S; the workers of ``--workers``
inherit both): the group's :data:`texsense.station.lease.READY_S` set to that many seconds, as
tests/monitor/test_group_leases.py sets it in its own process. The 10 s of beats before a
member that (re)starts gets its mats is waiting that checks nothing in those tests (it was
~20 of the 37 s of the killed worker's test); what they check (the mats' share, the takeover,
the share back) is the same after 3 s of beats."""

import os

if os.environ.get("TEXSENSE_TEST_READY_S"):
    from texsense.station import lease

    lease.READY_S = float(os.environ["TEXSENSE_TEST_READY_S"])
