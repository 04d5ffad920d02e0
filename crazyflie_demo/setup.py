from catkin_pkg.python_setup import generate_distutils_setup
from setuptools import setup

setup(**generate_distutils_setup(packages=['crazyflie_demo', 'pycrazyswarm', 'pycrazyswarm.cfsim', 'uav_trajectory'],
                                 package_dir={'': 'src'}))
