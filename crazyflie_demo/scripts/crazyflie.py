#!/usr/bin/env python3
"""crazyflie_ros HEAD's wrapper class: ``import crazyflie`` in a script next to this one, then
``cf = crazyflie.Crazyflie("/crazyflie", tf.TransformListener())`` (crazyflie_demo/crazyflie_wrapper.py)."""
import sys

from crazyflie_demo.crazyflie_wrapper import Crazyflie, arrayToGeometryPoint

# In a catkin devel space, `import crazyflie` finds a relay file that runs this one in a namespace of
# its own; hand the names to the module being imported so that `crazyflie.Crazyflie` works there too.
if __name__ != "__main__" and sys.modules.get(__name__) is not None:
    sys.modules[__name__].Crazyflie = Crazyflie
    sys.modules[__name__].arrayToGeometryPoint = arrayToGeometryPoint
