from setuptools import setup
from catkin_pkg.python_setup import generate_distutils_setup

setup(**generate_distutils_setup(
    packages=['crazyflie_driver', 'crazyflie_driver.sim', 'crazyflie_driver.mocap',
              'crazyflie_driver.nodes'],
    package_dir={'': 'src'},
))
