"""The Allan check of one IMU: its current terms against the baseline, every ``check_s`` of message time.

Per axis the reported terms (:meth:`EstimatorBank.report_terms`) give the parameters the window resolves
(health.baseline.check_params); of those, the ones the estimators' own Allan curves support are compared
with the baseline (companion.health.degradation), and a rise counts only where the measured curves show it
against the levels the baseline was learned from (health.baseline.risen_params). A raised gyro term sets
the IMU's ``allan`` fault, so the fault code and the health flag carry it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from companion.health.baseline import check_params, risen_params, rounding_ceiling, supported_params
from companion.health.degradation import DEGRADING, HealthDetector, Transition
from companion.health.hold import FAULT, OK
from companion.health.monitor import ImuFaults
from companion.samples import GYRO_AXES
from companion.service.baseline_match import units_mismatch
from companion.service.estimator_bank import EstimatorBank

Params = dict[str, tuple[float, float]]  # {param: (value, one-sigma)}


class CheckResult(NamedTuple):
    """What one check gives: the reported terms per axis (empty before ``min_report_s`` of still data), the
    health transitions, and an error line when a loaded baseline is of other units or another sensor."""

    reported: dict[str, list[dict]]
    transitions: list[Transition]
    error: str | None = None


@dataclass
class StreamFacts:
    """What the check needs to know of the stream: the IMU, its rate and gyro LSB (the rounding floor)."""

    imu: int
    rate_hz: float | None
    gyro_lsb: float | None


class AllanCheck:
    """The degradation detector of one IMU and the parameters of its last check (:attr:`current`)."""

    def __init__(self, imu: int, cfg):
        self.cfg = cfg  # service.pipeline_config.PipelineConfig
        self.detector = HealthDetector(imu, cfg.health)
        self.current: dict[str, Params] = {}  # per axis the parameters the last check resolved

    def supported(self, bank: EstimatorBank, ax: str, params: Params) -> Params:
        """The current parameters the estimators' own Allan curves support (health.baseline.supported_params)."""
        return bank.per_estimator(ax, params, lambda sub, lv: supported_params(sub, *lv, z=self.cfg.health.z))

    def risen(self, bank: EstimatorBank, ax: str, params: Params, base, base_levels) -> Params:
        """The current parameters whose rise over the baseline the measured Allan curves show
        (health.baseline.risen_params), each against the levels the baseline was learned from."""
        return bank.per_estimator(ax, params,
                                  lambda sub, lv: risen_params(sub, base, lv, base_levels, z=self.cfg.health.z))

    def run(self, bank: EstimatorBank, axes, stream: StreamFacts, faults: ImuFaults, baseline,
            strict: bool) -> CheckResult:
        """One check over ``axes`` (the bank flushed, at least ``min_report_s`` fed); ``strict``: a loaded,
        not forced baseline must be of this stream's units and sensor."""
        reported: dict[str, list[dict]] = {}
        transitions: list[Transition] = []
        for ax in axes:
            terms = bank.report_terms(ax)
            cur = check_params(terms, side="current")
            self.current[ax] = cur
            cur = self.supported(bank, ax, cur)
            reported[ax] = terms
            base = baseline.get(stream.imu, ax) if baseline is not None else None
            if base is None or bank.learn:
                continue
            bad = units_mismatch(base, cur) if strict else None
            if bad:
                return CheckResult(reported, transitions,
                                   f"baseline {baseline.source} does not match IMU{stream.imu} {ax}: "
                                   f"{bad}; use a baseline of this stream or --baseline-force")
            shown = self.risen(bank, ax, cur, base, baseline.get_levels(stream.imu, ax))
            # a raised flag clears on the unshown ones too: a value that stays a little above a baseline
            # learned low must not hold "degrading" after the rise has gone
            unshown = {p: v for p, v in cur.items() if p not in shown}
            if ax in GYRO_AXES:
                base = rounding_ceiling(base, stream.rate_hz, stream.gyro_lsb)
            for tr in self.detector.check(ax, shown, base, unshown):
                transitions.append(tr)
                if ax in GYRO_AXES:
                    faults.set_external("allan", ax, FAULT if self.degrading(ax) else OK)
        return CheckResult(reported, transitions)

    def degrading(self, ax: str) -> bool:
        return any(d.state == DEGRADING for (a, _), d in self.detector.detectors.items() if a == ax)

    def worst(self, ax: str) -> tuple[float, str]:
        """(ratio, param) of the largest degrading Allan term of an axis."""
        worst = [(d.ratio, p) for (a, p), d in self.detector.detectors.items() if a == ax and d.state == DEGRADING]
        return max(worst) if worst else (math.nan, "N")


def bias_extra_var(baseline, imu: int, block_s: float) -> dict[str, float]:
    """Per gyro axis the Allan-predicted variance of a block mean's wander around the bias reference,
    0.44 B^2 + K^2 T / 3 with T the reference's span (REF_TAU_BLOCKS blocks): the bias tests allow for it."""
    from companion.health.bias import REF_TAU_BLOCKS

    out = {}
    for ax in GYRO_AXES:
        b = baseline.get(imu, ax) if baseline is not None else None
        if not b:
            continue
        v = 0.0
        if "B" in b and math.isfinite(b["B"][0]):
            v += 0.44 * b["B"][0] ** 2
        if "K" in b and math.isfinite(b["K"][0]):
            v += b["K"][0] ** 2 * REF_TAU_BLOCKS * block_s / 3.0
        out[ax] = v
    return out
