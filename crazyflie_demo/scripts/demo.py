#!/usr/bin/env python3
"""The chapter's waypoint demo: ``from demo import Demo`` in a script next to this one, or run on its
own with the waypoints [x, y, z, yaw (rad), sleep (s)] in the private parameter ~waypoints.
Importing it starts nothing; Demo(goals).run() starts the node."""
import sys

from crazyflie_demo.waypoint_demo import Demo, main

# In a catkin devel space, `import demo` finds a relay file that runs this one in a namespace of
# its own; hand Demo to the module being imported so that `from demo import Demo` works there too.
if __name__ != "__main__" and sys.modules.get(__name__) is not None:
    sys.modules[__name__].Demo = Demo

if __name__ == "__main__":
    main()
