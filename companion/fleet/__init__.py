"""Fleet analysis: thousands of logs on Dask, a results database, gyro trends across flights, a report.

One module per concern (data flows one way, top to bottom):

- :mod:`~companion.fleet.discover`  LOGS arguments (files, folders, globs) to log files; content hashes
- :mod:`~companion.fleet.identity`  vehicle and IMU identity and start time found in a log's metadata
- :mod:`~companion.fleet.task`      the per-log analysis (the very code of ``companion analyze``); never raises
- :mod:`~companion.fleet.store`     the SQLite results database (schema, one writer, idempotent by hash)
- :mod:`~companion.fleet.trends`     the trend test across flights (numpy/scipy only)
- :mod:`~companion.fleet.dask_runner`    the Dask runner (local cluster of processes or a given scheduler)
- :mod:`~companion.fleet.fleet_ranking`    ranking, JSON and the self-contained HTML report
- :mod:`~companion.fleet.synthetic_fleet`  a synthetic fleet in which chosen IMUs degrade slowly

Nothing here is imported by the rest of companion; dask and matplotlib are imported only where used.
Documentation: docs/fleet.md.
"""
