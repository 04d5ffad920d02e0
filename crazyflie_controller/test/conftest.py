"""The unit tests below import their helpers from the ``controller_support`` package next to this file."""
import os
import sys

_HERE = os.path.dirname(os.path.abspath(__file__))
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)
