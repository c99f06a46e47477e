"""Baseline noise coefficients of each gyro axis: what "healthy" looked like.

A baseline holds, per IMU and axis, the linear Allan terms (Q, N, B, K, R; SI units) with a one-sigma
uncertainty each: ``{"N": (value, std), "B": (value, std), ...}``. It is learned from the first
seconds of still data of a run (an estimator's ``terms()``, whose ``std`` entries are used as is) or
read from a file written by ``companion analyze`` (fitted terms with 95 % intervals ``ci95``, turned
into a one-sigma figure as std = (hi - lo) / (2 * 1.96), the normal approximation).

numpy only; no I/O here except plain dicts (the caller reads JSON/YAML).
"""

from __future__ import annotations

import math
from typing import Iterable, Mapping

import numpy as np

from companion.allan.special import Z95
from companion.allan.terms import LINEAR_PARAM, avar_term
from companion.health.noise import quantized_ceiling

#: parameter -> effect, for the linear terms (Miao 2014 eq. (3.5): x = [Q N B K R]).
PARAM_EFFECT = {p: e for e, p in LINEAR_PARAM.items()}


def params_from_terms(terms: Iterable[Mapping]) -> dict[str, tuple[float, float]]:
    """Terms (canonical dicts) -> ``{param: (value, std)}`` for the linear parameters present.

    ``std`` comes from ``term["std"][param]`` (online estimators) or from ``term["ci95"][param]``
    (offline fits); it is ``inf`` when neither is given (such a value never triggers a flag).
    """
    out: dict[str, tuple[float, float]] = {}
    for term in terms or ():
        effect = term.get("effect")
        p = LINEAR_PARAM.get(effect)
        if p is None or p not in term:
            continue
        value = float(term[p])
        std = math.inf
        if isinstance(term.get("std"), Mapping) and p in term["std"]:
            std = float(term["std"][p])
        elif isinstance(term.get("ci95"), Mapping) and p in term["ci95"]:
            lo, hi = term["ci95"][p]
            std = (float(hi) - float(lo)) / (2.0 * Z95)
        if math.isfinite(value) and value >= 0.0 and not math.isnan(std):
            out[p] = (value, abs(std))
    return out


def check_params(terms: Iterable[Mapping], side: str = "current") -> dict[str, tuple[float, float]]:
    """``{param: (value, s)}`` of the resolved linear terms for the degradation test (degradation.py), where
    ``s / value`` is the one-sigma of ln(value) read from the side of the 95 % interval the test looks at.

    The test asks whether the current value's *lower* end is above the baseline's *upper* end. The intervals
    of B and K from a short window are far from symmetric (scaled chi-square with few degrees of freedom;
    K 2.6e-3 [0, 7.4e-3] rad/s^1.5 was reported with a 1-sigma of 1.9e-3, and ln(x/b) - 3 sigma_L with that
    symmetric sigma flagged `K 24.7x` on a healthy gyro), so the one-sigma of ln(x) is taken from the
    interval's end: ln(value / lo) / 1.96 for the current value (``side="current"``), ln(hi / value) / 1.96
    for the baseline (``side="baseline"``).

    A current term whose interval reaches 0 is not resolved by the window and is left out (it is no value
    to compare); such a baseline term is kept with a one-sigma of at least its value, which the detector
    treats as unresolved (tested against its upper bound). Terms without an interval (the Miao estimator)
    keep their one-sigma as is; bounds (``"bound": True``) are left out.
    """
    out: dict[str, tuple[float, float]] = {}
    for term in terms or ():
        p = LINEAR_PARAM.get(term.get("effect"))
        if not p or term.get("bound") or p not in term:
            continue
        v = float(term[p])
        if not (math.isfinite(v) and v > 0.0):
            continue
        ci = (term.get("ci95") or {}).get(p)
        if ci is None:
            s = float((term.get("std") or {}).get(p, math.inf))
            if not math.isnan(s):
                out[p] = (v, abs(s))
            continue
        lo, hi = float(ci[0]), float(ci[1])
        if side == "current":
            if lo > 0.0 and lo < v:
                out[p] = (v, v * math.log(v / lo) / Z95)
            continue
        if lo > 0.0 and math.isfinite(hi) and hi > v:
            out[p] = (v, v * math.log(hi / v) / Z95)
        else:
            out[p] = (v, max((hi - lo) / (2.0 * Z95), v))
    return out


#: cluster times below this are not used to judge whether the Allan curve supports a coefficient: there the
#: autopilot's low-pass filter bends the white-noise curve below N^2 / tau (a bound from them would be too low)
SUPPORT_MIN_TAU_S = 1.0


def supported_params(params: Mapping[str, tuple[float, float]], tau, avar, edf, z: float = 3.0,
                     min_tau: float = SUPPORT_MIN_TAU_S) -> dict[str, tuple[float, float]]:
    """The entries of ``params`` (``{param: (value, s)}``) whose own Allan variance the measured curve supports.

    A term's contribution p^2 basis(tau) cannot exceed the Allan variance measured at any cluster time: the
    other terms only add to it. With ``edf`` chi-square degrees of freedom per level, the true AVAR is below
    avar edf / chi2_lo(edf) at z sigma (Wilson-Hilferty quantile; no limit where that is undefined, i.e.
    for levels with few degrees of freedom). A coefficient above that at some level tau >= ``min_tau`` is a
    fit that left the data (the GLS of a misfitting model with strongly correlated levels can put a
    coefficient far outside every measured point: K 3.0e-3 rad/s^1.5 on a curve whose ADEV at 262 s was
    3.1e-4 rad/s, where K alone gives 0.028) and is not compared with the baseline. A real rise of the
    term raises the measured curve with it, so it stays supported.
    """
    tau, avar, edf = (np.asarray(x, float) for x in (tau, avar, edf))
    use = (tau >= min_tau) & (avar > 0) & (edf > 0)
    if not use.any():
        return dict(params)
    tau, avar, edf = tau[use], avar[use], edf[use]
    a = 2.0 / (9.0 * edf)
    q = 1.0 - a - z * np.sqrt(a)  # Wilson-Hilferty: chi2_lo / edf = q^3
    upper = np.where(q > 0, avar / np.maximum(q, 1e-12) ** 3, np.inf)
    out = {}
    for p, (v, s) in params.items():
        effect = PARAM_EFFECT.get(p)
        if effect is None:
            out[p] = (v, s)
            continue
        basis = avar_term({"effect": effect, p: 1.0}, tau)
        ok = basis > 0
        cap2 = float(np.min(upper[ok] / basis[ok])) if ok.any() else math.inf
        if v * v <= cap2:
            out[p] = (v, s)
    return out


def rounding_ceiling(base: Mapping[str, tuple[float, float]] | None, rate_hz: float | None,
                     lsb: float | None) -> Mapping[str, tuple[float, float]] | None:
    """The baseline of a rounded (int16) gyro axis as the degradation test must read it: N raised to the
    largest white level the rounding can give a gyro of that noise (the noise detector's rule,
    :func:`companion.health.noise.quantized_ceiling`).

    A gyro whose noise is below about half an LSB per sample (ArduPilot SITL over RAW_IMU: 0.2 LSB) shows
    an N that depends on where its bias sits between two codes: near a code's centre it rarely leaves it,
    near a boundary it flips between two; a bias drifting across the code grid moves N by up to the square
    root of that ceiling (2.3x at 0.21 LSB) with no change of the gyro. The per-sample std in LSB is
    N sqrt(rate) / LSB (IEEE 952 two-sided density); above 0.75 LSB the factor is 1 and the baseline is
    returned as it is. Float data (``lsb`` None) likewise."""
    if not base or "N" not in base or not lsb or not rate_hz:
        return base
    n, s = base["N"]
    c = quantized_ceiling(n * math.sqrt(rate_hz) / lsb)
    if c <= 1.0:
        return base
    out = dict(base)
    out["N"] = (n * math.sqrt(c), s * math.sqrt(c))
    return out


def rise_z(ratio, nu1, nu2):
    """z-score of a ratio of two Allan variance estimates avar_now / avar_base against equality, each a scaled
    chi-square with nu1 and nu2 equivalent degrees of freedom, so that the ratio is F(nu1, nu2) when the
    true variances are equal. Paulson's normal approximation of the F distribution (Johnson, Kotz &
    Balakrishnan, Continuous Univariate Distributions vol. 2, ch. 27): at the exact 3-sigma quantile of F it
    gives z 2.95-3.00 for nu1, nu2 >= 10 and less for fewer (1.6 at nu1 = nu2 = 1, 2.8 at 4 and 4): with few
    degrees of freedom it asks for a larger ratio than the exact test, never a smaller one:

        z = ((1 - 2 / (9 nu2)) r^(1/3) - (1 - 2 / (9 nu1))) / sqrt(2 / (9 nu2) r^(2/3) + 2 / (9 nu1))
    """
    r, a1, a2 = (np.asarray(x, float) for x in (ratio, nu1, nu2))
    a1, a2 = 2.0 / (9.0 * a1), 2.0 / (9.0 * a2)
    c = np.cbrt(np.maximum(r, 0.0))
    return ((1.0 - a2) * c - (1.0 - a1)) / np.sqrt(a2 * c * c + a1)


def risen_params(params: Mapping[str, tuple[float, float]], base: Mapping[str, tuple[float, float]],
                 now_levels, base_levels, z: float = 3.0) -> dict[str, tuple[float, float]]:
    """The entries of ``params`` whose rise over the baseline the measured Allan curves show.

    A coefficient is a projection of the Allan curve on the selected model, and two selections of the same
    data can project it differently: a Gauss-Markov bias the model lacks looks like a random walk of
    sigma sqrt(2 / tau_c) below its correlation time and like a bias instability near it, and which of the
    two takes it moves with the record (a healthy copter hour: K 1.9e-5 rad/s^1.5 in the 600 s baseline,
    5.7e-5 in the selection at 1000 s on levels within 2 % of the ones before it, each with an interval of
    +-10 to 25 %: `K 3.1x baseline`). A real rise of a term raises the curve where the term matters. So a
    value above its baseline is compared only when some cluster time tau shows it: where the claimed rise
    (x^2 - b^2) basis(tau) is at least a quarter of the baseline's measured AVAR there, the measured ratio
    avar_now / avar_base is above 1 at ``z`` (:func:`rise_z`, the two as independent estimates: they
    share the baseline's data, which only makes the test harder to pass). Values at or below the baseline
    are always kept (they only ever clear a flag). ``now_levels`` / ``base_levels``: ``(tau, avar, edf)``,
    matched by cluster time; without the baseline's levels (a baseline read from a file) ``params`` is
    returned as is.
    """
    if base_levels is None or now_levels is None:
        return dict(params)
    tn, an, en = (np.asarray(x, float) for x in now_levels)
    tb, ab, eb = (np.asarray(x, float) for x in base_levels)
    kn, kb = np.round(tn * 1e6).astype(np.int64), np.round(tb * 1e6).astype(np.int64)
    common, i_n, i_b = np.intersect1d(kn, kb, return_indices=True)
    out = {}
    for p, (x, s) in params.items():
        b = base.get(p, (0.0, 0.0))[0] if base else 0.0
        effect = PARAM_EFFECT.get(p)
        if effect is None or not (math.isfinite(b) and x > b) or common.size == 0:
            out[p] = (x, s)
            continue
        tau, a_now, a_base = tn[i_n], an[i_n], ab[i_b]
        nu1, nu2 = en[i_n], eb[i_b]
        ok = (a_now > 0) & (a_base > 0) & (nu1 > 0) & (nu2 > 0)
        claim = (x * x - b * b) * avar_term({"effect": effect, p: 1.0}, tau)
        where = ok & (claim >= 0.25 * np.where(ok, a_base, np.inf))
        if where.any() and float(np.max(rise_z(a_now[where] / a_base[where], nu1[where], nu2[where]))) > z:
            out[p] = (x, s)
    return out


class Baseline:
    """Healthy reference per ``(imu, axis)``: ``{param: (value, std)}`` in SI units.

    ``source`` says where it came from ("learned" from still data of this run, or a file name).
    """

    FORMAT = "companion-baseline"

    def __init__(self, source: str = "learned"):
        self.source = source
        self.axes: dict[tuple[int, str], dict[str, tuple[float, float]]] = {}
        # per (imu, axis): the Allan levels (tau, avar, edf) the learned terms were fitted to (risen_params)
        self.levels: dict[tuple[int, str], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        # per IMU: the stream the baseline was measured on (message, rate_hz, gyro_lsb, units: a baseline of another stream would raise false alarms),
        # checked against the live stream by companion.service.baseline_match
        self.meta: dict[int, dict] = {}

    def set_axis(self, imu: int, axis: str, params: Mapping[str, tuple[float, float]]) -> None:
        self.axes[(int(imu), str(axis))] = {p: (float(v), float(s)) for p, (v, s) in params.items()}

    def get(self, imu: int, axis: str) -> dict[str, tuple[float, float]] | None:
        return self.axes.get((int(imu), str(axis)))

    def set_levels(self, imu: int, axis: str, tau, avar, edf) -> None:
        self.levels[(int(imu), str(axis))] = tuple(np.asarray(x, float).copy() for x in (tau, avar, edf))

    def get_levels(self, imu: int, axis: str):
        return self.levels.get((int(imu), str(axis)))

    def drop_imu(self, imu: int) -> None:
        """Forget one IMU's terms, levels and stream (its baseline is learned again)."""
        self.axes = {k: v for k, v in self.axes.items() if k[0] != int(imu)}
        self.levels = {k: v for k, v in self.levels.items() if k[0] != int(imu)}
        self.meta.pop(int(imu), None)

    def has_imu(self, imu: int) -> bool:
        return any(k[0] == int(imu) for k in self.axes)

    def __len__(self) -> int:
        return len(self.axes)

    # --- persistence (plain dicts, JSON-safe) ---
    def to_dict(self) -> dict:
        axes = {}
        for (imu, axis), params in sorted(self.axes.items()):
            axes.setdefault(f"IMU{imu}", {})[axis] = {p: {"value": v, "std": _finite_or_none(s)} for p, (v, s) in params.items()}
        levels = {}
        for (imu, axis), (tau, avar, edf) in sorted(self.levels.items()):
            levels.setdefault(f"IMU{imu}", {})[axis] = {"tau": tau.tolist(), "avar": avar.tolist(), "edf": edf.tolist()}
        return {"format": self.FORMAT, "version": 1, "source": self.source, "imus": axes,
                "streams": {f"IMU{imu}": dict(m) for imu, m in sorted(self.meta.items())}, "levels": levels}

    @classmethod
    def from_dict(cls, data: Mapping) -> "Baseline":
        """Read what :meth:`to_dict` wrote, or the JSON/YAML report of ``companion analyze``.

        Raises ValueError with one clear line when nothing usable is found.
        """
        if not isinstance(data, Mapping):
            raise ValueError("baseline file does not hold a mapping")
        if data.get("format") == cls.FORMAT:
            b = cls(str(data.get("source", "file")))
            for imu_name, axes in (data.get("imus") or {}).items():
                imu = _imu_index(imu_name)
                for axis, params in (axes or {}).items():
                    b.set_axis(imu, axis, {p: (float(d["value"]), math.inf if d.get("std") is None else float(d["std"]))
                                           for p, d in params.items()})
            if not b.axes:
                raise ValueError("baseline file holds no axes")
            b.meta = {_imu_index(k): dict(v) for k, v in (data.get("streams") or {}).items() if isinstance(v, Mapping)}
            for imu_name, axes in (data.get("levels") or {}).items():
                for axis, lv in (axes or {}).items():
                    try:
                        tau, avar, edf = (np.asarray(lv[k], float) for k in ("tau", "avar", "edf"))
                    except (KeyError, TypeError, ValueError):
                        continue  # levels are an aid: a damaged entry leaves that axis on the coefficients alone
                    if tau.shape == avar.shape == edf.shape and tau.ndim == 1:
                        b.set_levels(_imu_index(imu_name), axis, tau, avar, edf)
            return b
        return cls._from_analyze(data)

    @classmethod
    def _from_analyze(cls, data: Mapping) -> "Baseline":
        """Walk an ``analyze`` report: any mapping with an axis name (gx, gy, gz) whose value holds ``terms``.
        Each term's one-sigma is read as a learned baseline's is (:func:`check_params`, ``side="baseline"``:
        from the upper end of its 95 % interval), so that a baseline from a file and one learned from the same
        data are tested alike.

        The IMU index is taken from the nearest enclosing ``instance`` key (StreamKey.instance), else 0.
        """
        b = cls("analyze")
        _walk_analyze(data, b, imu=0)
        if not b.axes:
            raise ValueError("no fitted gyro terms found in the baseline file (expected a companion analyze report)")
        return b


def _walk_analyze(node, b: Baseline, imu: int) -> None:
    if isinstance(node, Mapping):
        if "instance" in node and isinstance(node["instance"], int):
            imu = node["instance"]
            if "message" in node and "rate_hz" in node and imu not in b.meta:  # an analyze stream entry (SI)
                gx = (node.get("axes") or {}).get("gx") or {}
                lsb = (gx.get("quantization") or {}).get("lsb") if isinstance(gx, Mapping) else None
                b.meta[imu] = {"message": node["message"], "rate_hz": node["rate_hz"], "gyro_lsb": lsb,
                               "units": "SI"}
        elif isinstance(node.get("key"), Mapping) and isinstance(node["key"].get("instance"), int):
            imu = node["key"]["instance"]
        for k, v in node.items():
            if k in ("gx", "gy", "gz") and isinstance(v, (Mapping, list)):
                terms = v.get("terms") if isinstance(v, Mapping) else v
                if isinstance(terms, list):
                    params = check_params([t for t in terms if isinstance(t, Mapping)], side="baseline")
                    if params:
                        b.set_axis(imu, k, params)
                        continue
            if isinstance(node.get("axis"), str) and k == "terms" and isinstance(v, list):
                params = check_params([t for t in v if isinstance(t, Mapping)], side="baseline")
                if params and node["axis"] in ("gx", "gy", "gz"):
                    b.set_axis(imu, node["axis"], params)
                continue
            _walk_analyze(v, b, imu)
    elif isinstance(node, list):
        for v in node:
            _walk_analyze(v, b, imu)


def _imu_index(name) -> int:
    s = str(name)
    if s.upper().startswith("IMU"):
        s = s[3:]
    try:
        return int(s)
    except ValueError:
        raise ValueError(f"baseline: bad IMU name {name!r} (expected IMU0, IMU1, ...)") from None


def _finite_or_none(x: float):
    return x if math.isfinite(x) else None
