"""A small quadrotor model for the controller's tests (not the project's simulator).

Point mass with a first-order motor lag, attitude that follows the commanded angles with a
first-order lag, the Förster thrust map, a ground, and a motion-capture stream (rate, latency,
noise). cmd_vel is mapped to the firmware's roll/pitch/yaw-rate/thrust as crazyflie_server does,
and the firmware's sign conventions turn those into motion:
roll > 0 → accelerates to −y, pitch > 0 (nose up) → −x, yaw rate > 0 → clockwise (yaw decreases).
"""
from __future__ import annotations

import math
import random
from collections import deque

from crazyflie_controller.position_controller import Command, PoseSample, PositionController
from crazyflie_driver.server.setpoint import setpoint_from_twist

G = 9.81


def thrust_newtons(u: float) -> float:
    """Förster's map for one motor (N) from the 16-bit command."""
    if u <= 0:
        return 0.0
    return 2.130295e-11 * u * u + 1.032633e-6 * u + 5.484560e-4


def hover_command(mass: float) -> float:
    a, b, c = 2.130295e-11, 1.032633e-6, 5.484560e-4 - mass * G / 4
    return (-b + math.sqrt(b * b - 4 * a * c)) / (2 * a)


class QuadModel:
    def __init__(self, mass: float = 0.032, motor_tau: float = 0.06, attitude_tau: float = 0.08,
                 mocap_rate: float = 100.0, mocap_latency: float = 0.01, mocap_noise: float = 0.0005,
                 position=(0.0, 0.0, 0.0), yaw: float = 0.0, seed: int = 1) -> None:
        self.mass, self.motor_tau, self.attitude_tau = mass, motor_tau, attitude_tau
        self.p = list(position)
        self.v = [0.0, 0.0, 0.0]
        self.yaw = yaw
        self.tilt_fwd = 0.0     # rad, positive accelerates along +x of the body
        self.tilt_right = 0.0   # rad, positive (right side down) accelerates along −y of the body
        self.u = 0.0            # motor command after the lag
        self.cmd = (0.0, 0.0, 0.0, 0.0)   # firmware roll, pitch [deg], yaw rate [deg/s], thrust
        self.t = 0.0
        self.mocap_period = 1.0 / mocap_rate
        self.mocap_latency, self.mocap_noise = mocap_latency, mocap_noise
        self._next_mocap = 0.0
        self._in_flight = deque()   # (time it becomes visible, PoseSample)
        self.latest_pose = None
        self._rng = random.Random(seed)

    def apply(self, command: Command, roll_trim: float = 0.0, pitch_trim: float = 0.0) -> None:
        """crazyflie_server's cmd_vel → RPYT mapping."""
        sp = setpoint_from_twist(command.linear_x, command.linear_y, command.linear_z, command.angular_z,
                                 roll_trim, pitch_trim)
        self.cmd = (sp.roll, sp.pitch, sp.yawrate, float(sp.thrust))

    def step(self, dt: float = 0.001) -> None:
        roll, pitch, yawrate, thrust = self.cmd
        if thrust < 1000:
            thrust = 0.0
        self.u += (thrust - self.u) * dt / self.motor_tau
        a = dt / self.attitude_tau
        self.tilt_fwd += (math.radians(-pitch) - self.tilt_fwd) * a
        self.tilt_right += (math.radians(roll) - self.tilt_right) * a
        self.yaw -= math.radians(yawrate) * dt
        f = 4 * thrust_newtons(self.u) / self.mass
        abx = f * math.sin(self.tilt_fwd)
        aby = -f * math.sin(self.tilt_right)
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        acc = [c * abx - s * aby, s * abx + c * aby,
               f * math.cos(self.tilt_fwd) * math.cos(self.tilt_right) - G]
        for i in range(3):
            self.v[i] += acc[i] * dt
            self.p[i] += self.v[i] * dt
        if self.p[2] <= 0.0:
            self.p[2] = 0.0
            self.v = [0.0, 0.0, max(0.0, self.v[2])]
        self.t += dt
        if self.t + 1e-9 >= self._next_mocap:
            self._next_mocap += self.mocap_period
            n = lambda: self._rng.gauss(0.0, self.mocap_noise)
            sample = PoseSample(self.t, self.p[0] + n(), self.p[1] + n(), self.p[2] + n(), self.yaw)
            self._in_flight.append((self.t + self.mocap_latency, sample))
        while self._in_flight and self._in_flight[0][0] <= self.t + 1e-9:
            self.latest_pose = self._in_flight.popleft()[1]


class Flight:
    """Runs a controller at ``rate`` Hz against a :class:`QuadModel`, recording z over time."""

    def __init__(self, controller: PositionController, model: QuadModel, rate: float = 50.0) -> None:
        self.controller, self.model = controller, model
        self.ticks_per_cycle = int(round(1.0 / rate / 0.001))
        self.log = []   # (t, x, y, z, yaw, command, state)
        self.pose_blackout = None  # (start, end) world times during which no pose reaches the controller
        self.pose_freeze = None    # (start, end) world times during which the mocap repeats one pose, stamped anew
        self._frozen = None

    def pose(self):
        if self.pose_blackout and self.pose_blackout[0] <= self.model.t < self.pose_blackout[1]:
            return None
        latest = self.model.latest_pose
        if latest is not None and self.pose_freeze and self.pose_freeze[0] <= self.model.t < self.pose_freeze[1]:
            if self._frozen is None:
                self._frozen = latest
            return self._frozen._replace(stamp=latest.stamp)
        self._frozen = None
        return latest

    def run(self, seconds: float) -> None:
        cycles = int(round(seconds / (self.ticks_per_cycle * 0.001)))
        for _ in range(cycles):
            cmd = self.controller.update(self.model.t, self.pose())
            self.model.apply(cmd)
            for _ in range(self.ticks_per_cycle):
                self.model.step(0.001)
            m = self.model
            self.log.append((m.t, m.p[0], m.p[1], m.p[2], m.yaw, cmd, self.controller.state))

    def takeoff(self) -> bool:
        return self.controller.takeoff(self.model.t, self.model.latest_pose)

    def settle_pose(self) -> None:
        """Lets the mocap deliver a first pose before anything else."""
        while self.model.latest_pose is None:
            self.model.step(0.001)
