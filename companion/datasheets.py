"""Datasheet noise figures of common autopilot gyros as a starting noise model (an adapter: reads YAML).

The figures live in ``companion/datasheets.yaml`` in the units the datasheets print; this module converts
them to the SI model terms of :mod:`companion.sim.model` (IEEE Std 952, two-sided PSDs):

* rate noise density d (deg/s/sqrt(Hz)) is one-sided: N = d (pi/180) / sqrt(2) rad/s/sqrt(Hz);
* angle random walk (deg/sqrt(h)), when the datasheet gives it, is N: N = ARW (pi/180) / 60
  (1 deg/sqrt(h) = 2.909e-4 rad/s/sqrt(Hz));
* in-run bias stability (deg/h) is the minimum of the Allan deviation curve, 0.664 B for flicker noise:
  B = figure (pi/180) / 3600 / 0.664 rad/s;
* LSB = (pi/180) / sensitivity rad/s.
"""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import yaml

from companion.errors import CompanionError

PATH = Path(__file__).with_name("datasheets.yaml")  #: the datasheet table shipped with the package
DEG = math.pi / 180.0  #: rad per deg
#: ADEV minimum of IEEE 952 flicker noise over B: sqrt(2 ln 2 / pi)
FLICKER_FLOOR = math.sqrt(2.0 * math.log(2.0) / math.pi)


def density_to_N(d_dps_rthz: float) -> float:
    """One-sided rate noise density (deg/s/sqrt(Hz)) -> IEEE 952 N (rad/s/sqrt(Hz), two-sided)."""
    return d_dps_rthz * DEG / math.sqrt(2.0)


def arw_to_N(arw_deg_rth: float) -> float:
    """Angle random walk (deg/sqrt(h)) -> N (rad/s/sqrt(Hz))."""
    return arw_deg_rth * DEG / 60.0


def stability_to_B(deg_h: float) -> float:
    """In-run bias stability (ADEV minimum, deg/h) -> IEEE 952 B (rad/s)."""
    return deg_h * DEG / 3600.0 / FLICKER_FLOOR


@lru_cache(maxsize=1)
def _table() -> dict:
    with open(PATH, encoding="utf-8") as f:
        return yaml.safe_load(f)


def _key(name: str) -> str:
    return "".join(ch for ch in name.upper() if ch.isalnum())


def names() -> list[str]:
    return list(_table())


def lookup(name: str) -> dict:
    """The datasheet entry of ``name`` (case, '-' and '_' ignored; 'ICM-42688-P' finds ICM-42688)."""
    table = _table()
    want = _key(name)
    for k, v in table.items():
        if _key(k) == want or (want.startswith(_key(k)) and len(want) - len(_key(k)) <= 2):
            return {"name": k, **v}
    raise CompanionError(f"unknown datasheet {name!r}; known: {', '.join(table)}")


def figures(entry: dict) -> dict:
    """SI figures of a datasheet entry: {N, N_from, B, lsb, filter_hz}."""
    if entry.get("arw_deg_rth"):
        N, src = arw_to_N(entry["arw_deg_rth"]), f"ARW {entry['arw_deg_rth']:g} deg/sqrt(h)"
    else:
        d = entry["noise_density_dps_rthz"]
        N, src = density_to_N(d), f"noise density {d * 1000:g} mdps/sqrt(Hz) (one-sided)"
    B = stability_to_B(entry["bias_stability_deg_h"]) if entry.get("bias_stability_deg_h") else None
    sens = entry.get("sensitivity_lsb_dps")
    return {"N": N, "N_from": src, "B": B,
            "B_from": f"bias stability {entry['bias_stability_deg_h']:g} deg/h" if B else None,
            "lsb": DEG / sens if sens else None, "filter_hz": entry.get("filter_hz")}


def model_terms(name: str) -> tuple[list[dict], dict]:
    """(gyro model terms in SI, the entry) of datasheet ``name``: white noise and, when specified, bias
    instability."""
    entry = lookup(name)
    fig = figures(entry)
    terms = [{"effect": "white_noise", "N": fig["N"]}]
    if fig["B"]:
        terms.append({"effect": "bias_instability", "B": fig["B"]})
    return terms, {**entry, **{"si": fig}}
