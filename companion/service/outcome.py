"""The exit status of a ``companion run`` (a replay, or the end of a live run) from its summary rows: a gyro
fault or degradation found, nothing usable, or healthy (the table in companion.errors and README)."""

from __future__ import annotations

from companion.errors import EXIT_FAULTS, EXIT_NO_DATA, EXIT_OK


def usable(row: dict) -> bool:
    """An IMU whose blocks reached the detectors: a known rate and at least one block cut (still or moving).
    A stream of gaps at an unknown rate (a CSV of whole-second times, a link that sent a few samples) is
    not."""
    c = row.get("counts") or {}
    return bool(row.get("rate_hz")) and (c.get("blocks_still", 0) + c.get("blocks_moving", 0)) > 0


def run_status(rows: list[dict]) -> tuple[int, str]:
    """(exit status, its one-line reason) of a run whose summary rows (service.imu_summary) are ``rows``:
    any active fault or a degrading IMU first (what the run is for), then no usable IMU, else healthy."""
    bad = [f"IMU{r['imu']}" for r in rows if r.get("faults") or r.get("health") == "degrading" or r.get("all_zero")]
    if bad:
        return EXIT_FAULTS, f"gyro faults or degradation found: {', '.join(bad)}"
    if not rows:
        return EXIT_NO_DATA, "no IMU data"
    if not any(usable(r) for r in rows):
        return EXIT_NO_DATA, (f"no usable IMU data: {', '.join('IMU%d' % r['imu'] for r in rows)} "
                              "without a known rate or a single block of samples")
    return EXIT_OK, "healthy"
