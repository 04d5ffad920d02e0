from catkin_pkg.python_setup import generate_distutils_setup
from setuptools import setup

setup(**generate_distutils_setup(
    packages=['crazyflie_driver', 'crazyflie_driver.crtp', 'crazyflie_driver.radio',
              'crazyflie_driver.protocol', 'crazyflie_driver.server', 'crazyflie_driver.server.swarm',
              'crazyflie_driver.mocap',
              'crazyflie_driver.sim', 'crazyflie_driver.sim.onboard', 'crazyflie_driver.sim.crtp',
              'crazyflie_driver.sim.room', 'crazyflie_driver.sim.air', 'crazyflie_driver.nodes'],
    package_dir={'': 'src'},
    package_data={'crazyflie_driver.sim.crtp': ['data/*.tsv', 'data/README.md']},
))
