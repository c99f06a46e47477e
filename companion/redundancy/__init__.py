"""Each IMU's own gyro noise in flight (or armed on the ground) from a vehicle's redundant IMUs (numpy/scipy).

Stable API
----------
::

    from companion.redundancy import ImuTrack, redundant_noise, fit_pair, align, PairCalibration
    tracks = [ImuTrack(t, gyro, rate_hz, filter_hz=20.0, lsb=None, label="IMU0"), ...]   # SI, 1-3 tracks
    res = redundant_noise(tracks, [(t0, t1), ...], still_n=None)
    res.per_imu[i]   # {"axes": {"gx": entry, ...}, "seconds": s, "method": "...", "notes": [...]}
    res.pairs        # [{"imus": [i, j], "calibration": {...}, "axes": {...}}]: each pair's figure
    # entry: companion analyze's axis form: "terms" (each with "ci95"), "bounds", "tau", "adev", ...

See :mod:`companion.redundancy.redundant` for the method, :mod:`~companion.redundancy.calibration` for the
relative calibration, :mod:`~companion.redundancy.hat` for the three-cornered hat.
"""

from companion.redundancy.align import Aligned, ImuTrack, align
from companion.redundancy.calibration import PairCalibration, fit_pair
from companion.redundancy.hat import hat_share, pair_points, quantization_avar
from companion.redundancy.redundant import ONE_IMU, OWN_NOISE, RedundancyResult, redundant_noise

__all__ = ["Aligned", "ImuTrack", "ONE_IMU", "OWN_NOISE", "PairCalibration", "RedundancyResult", "align",
           "fit_pair", "hat_share", "pair_points", "quantization_avar", "redundant_noise"]
