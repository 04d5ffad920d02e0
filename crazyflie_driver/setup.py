from catkin_pkg.python_setup import generate_distutils_setup
from setuptools import setup

setup(**generate_distutils_setup(
    packages=['crazyflie_driver', 'crazyflie_driver.crtp', 'crazyflie_driver.radio',
              'crazyflie_driver.protocol', 'crazyflie_driver.server', 'crazyflie_driver.server.swarm',
              'crazyflie_driver.mocap',
              'crazyflie_driver.sim', 'crazyflie_driver.sim.world', 'crazyflie_driver.sim.firmware',
              'crazyflie_driver.sim.air', 'crazyflie_driver.nodes'],
    package_dir={'': 'src'},
    package_data={'crazyflie_driver.sim.firmware': ['data/*.tsv', 'data/README.md']},
))
