"""Datasheet figures -> SI noise model: the unit conversions against independent arithmetic and
REFERENCE.md's constants, and the packaged table."""

import math

import numpy as np
import pytest

from companion import datasheets
from companion.errors import CompanionError
from companion.sim.synth import synthesize_axis
from companion.units import from_datasheet


def test_reference_constants():
    # ../shared/REFERENCE.md: 1 deg/sqrt(h) = 2.909e-4 rad/s/sqrt(Hz); 1 deg/h = 4.848e-6 rad/s
    assert datasheets.arw_to_N(1.0) == pytest.approx(2.909e-4, rel=1e-3)
    assert datasheets.arw_to_N(1.0) == pytest.approx(from_datasheet("N", 1.0))
    assert datasheets.stability_to_B(0.664 * 1.0) == pytest.approx(4.848e-6, rel=2e-3)


def test_one_sided_density_to_ieee_n():
    # 5 mdps/sqrt(Hz) one-sided = 5e-3 * pi/180 / sqrt(2) rad/s/sqrt(Hz) = 6.17e-5 = 0.212 deg/sqrt(h)
    N = datasheets.density_to_N(0.005)
    assert N == pytest.approx(6.171e-5, rel=1e-3)
    assert N / datasheets.arw_to_N(1.0) == pytest.approx(0.005 * 60 / math.sqrt(2), rel=1e-9)
    # ADIS16405 gives both: density 0.05 dps/sqrt(Hz) and ARW 2.0 deg/sqrt(h); one-sided reading agrees
    # with its ARW within 6 % (the two-sided reading would be 50 % off)
    e = datasheets.lookup("ADIS16405")
    ratio = datasheets.density_to_N(e["noise_density_dps_rthz"]) / datasheets.arw_to_N(e["arw_deg_rth"])
    assert 0.94 < ratio < 1.1


def test_one_sided_density_means_rms_over_bandwidth():
    # a one-sided density d: rms noise over the band 0..fs/2 is d sqrt(fs/2); the IEEE N simulated at fs
    # (sample std N sqrt(fs)) must give that rms
    d, fs = 0.01, 200.0
    N = datasheets.density_to_N(d)
    y = synthesize_axis([{"effect": "white_noise", "N": N}], fs, 200_000, np.random.default_rng(0))
    assert np.std(y) == pytest.approx(d * math.pi / 180 * math.sqrt(fs / 2), rel=0.01)


def test_bias_stability_is_the_adev_floor():
    from companion.allan.terms import avar_term

    B = datasheets.stability_to_B(25.2)
    floor = math.sqrt(avar_term({"effect": "bias_instability", "B": B}, np.array([100.0]))[0])
    assert floor * 180 / math.pi * 3600 == pytest.approx(25.2, rel=1e-3)


def test_every_listed_gyro_has_figures_and_a_source():
    want = ["MPU-6000", "MPU-9250", "ICM-20602", "ICM-20689", "ICM-42688", "BMI055", "BMI088", "ADIS16405",
            "ADIS16448"]
    assert set(want) <= set(datasheets.names())
    for name in want:
        terms, e = datasheets.model_terms(name)
        assert e["source"] and "Rev" in e["source"] or "DS" in e["source"]
        assert terms[0]["effect"] == "white_noise" and 1e-6 < terms[0]["N"] < 1e-3
        assert 1e-5 < e["si"]["lsb"] < 1e-2
    assert datasheets.lookup("icm42688p")["name"] == "ICM-42688"
    assert datasheets.lookup("mpu_6000")["name"] == "MPU-6000"
    # LSB at +-2000 dps: 1/16.4 deg/s = 1.064e-3 rad/s
    assert datasheets.model_terms("MPU-6000")[1]["si"]["lsb"] == pytest.approx(1.0642e-3, rel=1e-3)
    with pytest.raises(CompanionError, match="unknown datasheet"):
        datasheets.lookup("L3GD20")
