"""The tools' tests share the driver's test helpers: the ``support`` package in crazyflie_driver/test."""
import os
import sys

_SUPPORT_ROOT = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                             "crazyflie_driver", "test")
if _SUPPORT_ROOT not in sys.path:
    sys.path.insert(0, _SUPPORT_ROOT)
