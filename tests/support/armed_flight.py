"""A simulated DataFlash log of redundant IMUs armed from its first sample (no still data: the in-flight
analysis' case) and ``analyze``'s entries for it, shared by the in-flight analysis tests
(tests/analysis/conftest.py makes each one once per test process)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tests.redundancy.synthetic import flight


@dataclass(frozen=True)
class ArmedFlight:
    """The log, the truth (``n_true``: N of each IMU, rad/s/sqrt(Hz)) and analyze_source's result for gx, gy,
    gz (``entries``, ``summary``): read-only, shared by the tests that ask for the same flight."""

    path: Path
    n_true: np.ndarray
    entries: list
    summary: dict


def write_armed_flight(path, seed: int, n_true, seconds: float, offsets) -> Path:
    """tests.redundancy.synthetic.flight of len(n_true) IMUs (accel -9.8 m/s^2 on z), its first sample 1 s
    after boot and armed from 0.5 s, written as a 4.x DataFlash log at ``path``."""
    from companion.sim.dataflash_writer import write_imu_log

    t, g, _ = flight(seed, np.asarray(n_true, dtype=float), seconds=seconds, offsets=list(offsets))
    t = t + 1.0
    accel = np.zeros((len(g), t.shape[0], 3))
    accel[..., 2] = -9.8
    write_imu_log(path, t, np.array(g), accel, layout="4.x", armed=[(0.5, True)])
    return Path(path)


def analyse_armed_flight(folder, seed: int, n_true, seconds: float, offsets) -> ArmedFlight:
    """:func:`write_armed_flight` into ``folder``, then ``analyze``'s analysis of it (analyze_source)."""
    from companion.analysis.source import analyze_source

    path = write_armed_flight(Path(folder) / f"armed_{seed}_{len(n_true)}.bin", seed, n_true, seconds, offsets)
    entries, summary = analyze_source(str(path), ["gx", "gy", "gz"])
    return ArmedFlight(path, np.asarray(n_true, dtype=float), entries, summary)
