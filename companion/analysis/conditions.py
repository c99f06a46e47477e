"""The conditions of a log besides still: *ground* (armed, not moving: motors running on the ground) and
*flight* (armed and moving), from the log's armed state and the gyro's slow level (numpy only).

Motion: the gyro of one IMU stream averaged over WINDOW_S windows (2.5 sample periods for a slower stream); a window is *quiet* when those averages,
over the QUIET_SPAN_S around it, stay within QUIET_RAD_S of their median on every axis and the median is
below TURN_RAD_S (a vehicle on the ground with its motors running shows vibration, which averages out,
and no rotation; in the air the attitude control moves it by more). Ground = armed and quiet, flight =
armed and not quiet; each run shorter than MIN_RUN_S is dropped and EDGE_S is trimmed at both ends of a run
(spool-up, take-off, touch-down). Without an armed state in the source, motion alone: flight = not quiet,
and no ground condition (the motors' state is unknown).
"""

from __future__ import annotations

import warnings

import numpy as np

WINDOW_S = 0.5
QUIET_SPAN_S = 3.0
QUIET_RAD_S = 0.01  # 0.6 deg/s
TURN_RAD_S = 0.05
MIN_RUN_S = 5.0
EDGE_S = 1.0


def armed_windows(transitions, t_end: float) -> list[tuple[float, float]]:
    """[(t_on, t_off)] from armed transitions [(t, armed)] (armed at the end: until ``t_end``)."""
    out, on = [], None
    for t, a in sorted(transitions or [], key=lambda x: x[0]):
        if a and on is None:
            on = float(t)
        elif not a and on is not None:
            out.append((on, float(t)))
            on = None
    if on is not None and t_end > on:
        out.append((on, float(t_end)))
    return out


def _quiet(t: np.ndarray, gyro: np.ndarray, edges: np.ndarray, half: int, idx: np.ndarray | None = None) -> np.ndarray:
    """Per window [edges[k], edges[k+1]): quiet (see the module docstring); a window without samples is not.
    ``idx``: each sample's window, ``searchsorted(edges, t, "right") - 1``, where the caller has it."""
    nb = edges.shape[0] - 1
    if idx is None:
        idx = np.searchsorted(edges, t, side="right") - 1
    ok = (idx >= 0) & (idx < nb)
    if not np.isfinite(gyro).all():  # tested whole first: a row-wise test costs more than the rest of the step
        ok &= np.all(np.isfinite(gyro), axis=1)
    every = bool(ok.all())  # the usual case: no masked copies of the columns
    iok = idx if every else idx[ok]
    cnt = np.bincount(iok, minlength=nb).astype(float)
    mean = np.full((nb, 3), np.nan)
    for j in range(3):
        s = np.bincount(iok, weights=gyro[:, j] if every else gyro[ok, j], minlength=nb)
        mean[:, j] = np.where(cnt > 0, s / np.maximum(cnt, 1), np.nan)
    pad = np.full((half, 3), np.nan)
    win = np.lib.stride_tricks.sliding_window_view(np.vstack([pad, mean, pad]), 2 * half + 1, axis=0)
    # win: (nb, 3, 2 half + 1), the window means around each window
    enough = np.sum(np.all(np.isfinite(win), axis=1), axis=1) >= half + 1
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN spans: not quiet anyway
        med = np.nanmedian(win, axis=2)
        spread = np.nanmax(np.abs(win - med[:, :, None]), axis=2)
    quiet = enough & (cnt > 0) & np.all(spread <= QUIET_RAD_S, axis=1) & np.all(np.abs(med) <= TURN_RAD_S, axis=1)
    return quiet


def _runs(mask: np.ndarray, edges: np.ndarray) -> list[tuple[float, float]]:
    out = []
    k, n = 0, mask.shape[0]
    while k < n:
        if not mask[k]:
            k += 1
            continue
        j = k
        while j < n and mask[j]:
            j += 1
        a, b = float(edges[k]) + EDGE_S, float(edges[j]) - EDGE_S
        if b - a >= MIN_RUN_S:
            out.append((a, b))
        k = j
    return out


def condition_intervals(t: np.ndarray, gyro: np.ndarray, transitions, has_armed_state: bool) -> dict:
    """{"flight": [(t0, t1)], "ground": [(t0, t1)], "method": str} of one IMU stream's times ``t`` (s) and
    ``gyro`` (n, 3) rad/s with the log's armed ``transitions`` [(t, armed)]."""
    t = np.asarray(t, dtype=float)
    if t.shape[0] < 2:
        return {"flight": [], "ground": [], "method": "no data"}
    dt = np.diff(t)
    step = float(np.median(dt[dt > 0])) if np.any(dt > 0) else 1.0
    window = max(WINDOW_S, 2.5 * step)  # a slow stream (1-4 Hz telemetry): a few samples per window
    edges = np.arange(float(np.nanmin(t)), float(np.nanmax(t)) + window, window)
    if edges.shape[0] < 2:
        return {"flight": [], "ground": [], "method": "no data"}
    idx = np.searchsorted(edges, t, side="right") - 1  # each sample's window, for both steps below
    quiet = _quiet(t, np.asarray(gyro, dtype=float), edges, max(1, int(round(QUIET_SPAN_S / window / 2))), idx)
    mid = (edges[:-1] + edges[1:]) / 2.0
    has = np.bincount(np.clip(idx, 0, mid.shape[0] - 1), minlength=mid.shape[0]) > 0
    if not has_armed_state:
        return {"flight": _runs(~quiet & has, edges), "ground": [],
                "method": "motion only (no armed state in this source)"}
    armed = np.zeros(mid.shape[0], dtype=bool)
    for a, b in armed_windows(transitions, float(edges[-1])):
        armed |= (mid >= a) & (mid < b)
    return {"flight": _runs(armed & ~quiet & has, edges), "ground": _runs(armed & quiet & has, edges),
            "method": "armed state + motion"}
