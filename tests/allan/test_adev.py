"""Overlapping Allan deviation against the published NBS14 reference values (allantools/Stable32)."""

import numpy as np
import pytest

from companion.allan.adev import cluster_sizes, oadev


def nbs14_1000():
    n = 1234567890
    out = []
    for _ in range(1000):
        out.append(n / 2147483647)
        n = (16807 * n) % 2147483647
    return np.array(out)


def test_nbs14_oadev():
    _, adev, _, _ = oadev(nbs14_1000(), 1.0, m=[1, 10, 100])
    assert adev == pytest.approx([0.2922319, 0.09159953, 0.03241343], rel=1e-6)


def test_against_allantools_random():
    allantools = pytest.importorskip("allantools")
    y = np.random.default_rng(7).normal(3.0, 0.5, 20000)
    tau, adev, m, _ = oadev(y, 50.0, spec="octave")
    t2, a2, _, _ = allantools.oadev(y, rate=50.0, data_type="freq", taus="octave")
    assert tau[: len(t2)] == pytest.approx(t2)
    assert adev[: len(a2)] == pytest.approx(a2, rel=1e-9)


def test_cluster_sizes_bounds():
    assert list(cluster_sizes(9, "octave")) == [1, 2, 4]
    assert list(cluster_sizes(100, "decade")) == [1, 2, 4, 10, 20, 40]
    assert cluster_sizes(1, "octave").size == 0
    with pytest.raises(ValueError):
        cluster_sizes(100, "weekly")
