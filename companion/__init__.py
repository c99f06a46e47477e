"""companion: gyro health monitoring from MAVLink IMU data.

Data flows one way: source -> samples -> estimator -> health -> reporter.
The numerical core (``companion.allan``, ``companion.estimators``, ``companion.sim``,
``companion.gap``, ``companion.compensation``) imports only numpy and scipy.
"""

__version__ = "0.1.0"
