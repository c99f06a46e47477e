"""Online Allan-coefficient estimators (numpy/scipy only).

- :class:`OctaveBankEstimator` (``kind="octave"``, the default): recursive Allan accumulators at octave
  cluster sizes with staggered phases, coefficients by weighted non-negative least squares with 1-sigma.
- :class:`MiaoSHAKF` (``kind="miao"``): the paper-faithful Sage-Husa adaptive EKF of Miao et al. 2014.

Both share one interface: ``update(y)`` with a float or a 1-D block (identical results), ``terms()``,
``n_samples``, ``state_dict()`` / ``from_state_dict()``. :func:`make_estimator` builds one from the
``estimator:`` section of the configuration.
"""

from __future__ import annotations

from companion.estimators.octave_bank import DEFAULT_EFFECTS, OctaveBankEstimator

KINDS = ("octave", "miao")


def _miao():
    from companion.estimators.miao_shakf import MiaoSHAKF

    return MiaoSHAKF


def make_estimator(kind="octave", rate_hz=None, **cfg):
    """Build an online estimator. ``kind``: ``"octave"`` (default) or ``"miao"``; ``cfg``: keyword arguments
    of that class; settings of the other kind are ignored, unknown keys raise ValueError naming them.
    Sub-sections ``octave: {...}`` / ``miao: {...}`` are accepted and the matching one is merged in."""
    if rate_hz is None:
        raise ValueError("make_estimator needs rate_hz")
    kind = kind or "octave"
    if kind not in KINDS:
        raise ValueError(f"unknown estimator kind {kind!r}; expected one of: {', '.join(KINDS)}")
    cfg = dict(cfg)
    sub = {k: cfg.pop(k) for k in KINDS if k in cfg}
    cfg.update(sub.get(kind) or {})
    import inspect

    def keys(c):
        return set(inspect.signature(c.__init__).parameters) - {"self", "rate_hz"}

    cls = OctaveBankEstimator if kind == "octave" else _miao()
    other = _miao() if kind == "octave" else OctaveBankEstimator
    allowed = keys(cls)
    bad = sorted(set(cfg) - allowed - keys(other))
    if bad:
        raise ValueError(f"estimator kind {kind!r} has no setting {', '.join(bad)} (allowed: {', '.join(sorted(allowed))})")
    # settings of the other kind (one config section serves both) are ignored
    return cls(rate_hz, **{k: v for k, v in cfg.items() if k in allowed})


def online_terms(y, rate_hz, kind="octave", **cfg) -> list[dict]:
    """Run an online estimator over the samples ``y`` and return its final report: for the octave bank
    (``fit="model"``, the default) the model chosen from the data with every effect of the offline model as
    a candidate, each linear term resolved or as its 95 % upper bound (companion.estimators.online_report) -- the
    same code path as ``companion run``."""
    est = make_estimator(kind, rate_hz=rate_hz, **cfg)
    est.update(y)
    return est.terms(full=True) if kind == "octave" else est.terms()


def from_state_dict(d: dict):
    """Rebuild an estimator of either kind from its ``state_dict()``."""
    kind = d.get("kind") if isinstance(d, dict) else None
    if kind == "octave":
        return OctaveBankEstimator.from_state_dict(d)
    if kind == "miao":
        return _miao().from_state_dict(d)
    raise ValueError(f"not an estimator state (kind {kind!r})")


__all__ = ["OctaveBankEstimator", "make_estimator", "from_state_dict", "online_terms", "DEFAULT_EFFECTS", "KINDS"]
