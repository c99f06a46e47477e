"""companion: gyro health monitoring from MAVLink IMU data.

Data flows one way: source -> samples -> estimator -> health -> reporter.
The numerical core (``companion.allan``, ``companion.estimators``, ``companion.sim``,
``companion.gap``, ``companion.compensation``) imports only numpy and scipy.
"""

import os

__version__ = "0.1.0"

# One BLAS thread per process unless the user says otherwise (set before numpy loads, so it holds for the
# command line and whoever imports companion first). The arrays here are short (a block, a few dozen cluster
# times, a 16-column fit): OpenBLAS's extra threads only spin-wait, and beside other work they cost 5-30x the
# CPU of one thread on the same dot products (measured on a 2-core machine; the test suite's CPU fell by a
# third), CPU that a companion computer's receive loop and a fleet's other workers need.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
del _var
