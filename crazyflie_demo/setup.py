from setuptools import setup
from catkin_pkg.python_setup import generate_distutils_setup

setup(**generate_distutils_setup(packages=['crazyflie_demo', 'pycrazyswarm', 'pycrazyswarm.cfsim', 'uav_trajectory'],
                                 package_dir={'': 'src'}))
