"""``companion fleet``: analyse a fleet's logs on Dask into SQLite, report gyro trends, simulate a fleet.

One step per module: ``fleet_analyze``, ``fleet_report``, ``fleet_simulate``; the work is in
:mod:`companion.fleet`.
"""

from __future__ import annotations

import argparse

from companion.cli import fleet_analyze, fleet_report, fleet_simulate

DESCRIPTION = """\
A fleet's thousands of logs: every IMU's noise coefficients per flight, kept in a SQLite database, and
the IMUs whose N, B or K rise across flights named. Three steps:

  companion fleet simulate demo/ --vehicles 20 --flights 30       a synthetic fleet (3 IMUs degrade)
  companion fleet analyze demo/ --db fleet.sqlite --workers 2     analyse every log (Dask), resumable
  companion fleet report --db fleet.sqlite --html report.html     ranking, trends, plots

Method and database schema: docs/fleet.md.
"""


def register(subparsers) -> None:
    p = subparsers.add_parser("fleet", help="many logs on Dask into SQLite, gyro trends across flights, HTML report",
                              description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="fleet_command", metavar="STEP")
    p.set_defaults(func=lambda args: _help(p))
    fleet_analyze.register(sub)
    fleet_report.register(sub)
    fleet_simulate.register(sub)


def _help(p) -> int:
    p.print_help()
    return 2
