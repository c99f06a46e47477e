"""The sensor's noise model in a gap result: the model after, without the terms that belong to the log.

``companion gap --out-model`` writes this model (the file format of :mod:`companion.sim.model`, which
``companion simulate`` and ``gap --model`` read). The model after that gap evaluates also holds terms of the
*measurement*, which gap derives from the log on every run and which a file of the sensor must not carry:

* the rate rounding to the log's LSB (``quantization`` of form ``rate_lsb``: a white term
  N_q = LSB sqrt(tau0 / 12)). It is a property of the recording (int16 mrad/s RAW_IMU, say), and its N_q
  depends on the log's rate. Written into the model it would be counted twice: ``simulate --message RAW_IMU``
  rounds its output again, and wherever the log's rounding and the model's extra white term both stand;
* the low-pass filter and decimation put on the white noise (``cutoff_hz``, ``order``, ``integrate``):
  the autopilot's or the recorder's filter, a setting of the log; N stays the sensor's white noise;
* a temperature-driven rate: it needs the log's temperature record.

Read back with ``gap --model`` on the same log, the model gives the same "after" model once gap has
derived these terms again: rounding by its LSB step, the filter as a candidate, temperature as a candidate.
The written rate_hz is the data's (the CLI's doing): gap evaluated every term at it.
"""

from __future__ import annotations

#: keys of a model-after term that are not parameters of the sensor's noise
_NOT_SENSOR_KEYS = ("ci95", "cutoff_hz", "order", "integrate")


def rounding_index(result) -> int | None:
    """Index in ``result.terms_after`` of the white term gap added for the log's rate rounding, or None."""
    q = result.quantization
    if not q or not q.get("added"):
        return None
    first_added = len(result.terms_before)
    for i, t in enumerate(result.terms_after):
        # held at N_q by the workflow: the same float, on a term the model did not have
        if i >= first_added and t.get("effect") == "white_noise" and t.get("N") == q["N_q"]:
            return i
    return None


def rederived(terms: list[dict], result) -> bool:
    """Whether gap, reading ``terms`` back on the same log, adds the log's rate rounding again: the test of its
    LSB step (the white term N_q, every term held, lowers the deviance by more than chi^2_1(1 - ALPHA))."""
    from companion.gap.candidates import fit_terms
    from companion.gap.rate_rounding import delta_crit

    q = result.quantization
    fixed = range(len(terms) + 1)
    d_without = fit_terms(result.measured, terms, fixed=fixed, intervals=False).dev
    d_with = fit_terms(result.measured, terms + [{"effect": "white_noise", "N": q["N_q"]}], fixed=fixed,
                       intervals=False).dev
    return d_without - d_with > delta_crit(1)


def sensor_terms(result) -> tuple[list[dict], list[str]]:
    """(terms, left out): the model after of ``result`` as the sensor's terms, and in plain words each term
    of the log that was left out of them.

    The rate rounding is left out when a run on the same log derives it again (:func:`rederived`). Where it
    passed its level only beside a model term that was then recalibrated, it may fall short of it against
    the written terms; it is then written as the white term it is, so that the file still reads back as the
    model after (and gap does not add it twice: a second N_q makes the fit worse)."""
    skip = rounding_index(result)
    terms, left = [], []
    for i, t in enumerate(result.terms_after):
        if i == skip:
            continue
        if t.get("effect") == "temperature":
            left.append(f"temperature-driven rate {t['coef']:.3g} rad/s/K")
            continue
        if t.get("effect") == "white_noise" and t.get("cutoff_hz"):
            left.append(f"low-pass {t['cutoff_hz']:.3g} Hz (order {int(t.get('order', 2))}) on the white noise")
        terms.append({k: v for k, v in t.items() if k not in _NOT_SENSOR_KEYS})
    if skip is not None:
        q = result.quantization
        if rederived(terms, result):
            left.insert(0, f"rate rounding to the log's LSB {q['lsb']:.4g} (white N_q {q['N_q']:.3g})")
        else:
            terms.insert(skip - sum(1 for t in result.terms_after[:skip] if t.get("effect") == "temperature"),
                         {"effect": "white_noise", "N": q["N_q"]})
    return terms, left
