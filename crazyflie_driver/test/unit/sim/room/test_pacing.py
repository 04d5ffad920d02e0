"""World pacing: fixed speeds, the ``auto`` rule on made-up lag samples, the lag probe, speed changes."""
from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from crazyflie_driver.sim.onboard.ticks import FIRMWARE_TICK_S
from crazyflie_driver.sim.room import pacing
from crazyflie_driver.sim.room import world as world_module
from crazyflie_driver.sim.room.pacing import (
    LAG_BOUND_S,
    MIN_SPEED,
    RECOVER_WINDOWS,
    AutoSpeed,
    HostDelay,
    Pacing,
    PacingError,
    parse_pacing,
    read_schedstat,
    sibling_pids,
)
from crazyflie_driver.sim.room.world import World


def test_speed_settings_are_auto_or_a_number_and_anything_else_names_the_choice():
    assert parse_pacing("auto") == Pacing(True, 1.0)
    assert parse_pacing(" AUTO ") == Pacing(True, 1.0)
    assert parse_pacing("0.5") == Pacing(False, 0.5)
    assert parse_pacing(2) == Pacing(False, 2.0)
    assert parse_pacing(0.0) == Pacing(False, 0.0)
    for bad in ("fast", -1, "-0.5", float("nan"), True, None):
        with pytest.raises(PacingError, match="'auto' or a number"):
            parse_pacing(bad)


def test_auto_keeps_real_time_while_the_host_wakes_up_on_time():
    rule = AutoSpeed()
    for _ in range(20):
        assert rule.update(0.0001) == 1.0


def test_auto_slows_down_at_once_when_host_threads_wait_long_in_world_time():
    """4 ms of wait at speed 1 is 4 ms of world time, four times the bound: halved, at most, in one sample."""
    rule = AutoSpeed()
    assert rule.update(0.004) == pytest.approx(0.5)
    # 1.5 ms at 0.5 is 0.75 ms of world time: within the bound, above the calm level: the speed stays
    assert rule.update(0.0015) == pytest.approx(0.5)
    assert rule.lag_world_s == pytest.approx(0.00075)
    # 3 ms at 0.5 is 1.5 ms of world time: to where it would be 0.8 of the bound
    assert rule.update(0.003) == pytest.approx(0.5 * 0.8 * LAG_BOUND_S / 0.0015)


def test_auto_never_goes_below_its_floor():
    rule = AutoSpeed()
    for _ in range(30):
        rule.update(1.0)
    assert rule.speed == MIN_SPEED


def test_auto_returns_to_real_time_after_calm_samples_and_not_before():
    rule = AutoSpeed()
    rule.update(0.008)                      # down to 0.5
    slow = rule.speed
    for _ in range(RECOVER_WINDOWS - 1):
        assert rule.update(0.0) == slow     # one calm sample is not yet a recovery
    assert rule.update(0.0) > slow
    for _ in range(50):
        rule.update(0.0)
    assert rule.speed == 1.0
    rule.update(0.008)                      # a relapse starts the count again
    after = rule.speed
    assert rule.update(0.0) == after


def test_auto_takes_the_speed_the_world_itself_achieves_when_that_is_lower():
    rule = AutoSpeed()
    assert rule.update(0.0001, achieved=0.6) == pytest.approx(0.6)
    assert rule.update(0.0001, achieved=0.59) == pytest.approx(0.6)    # within 5 %: not behind
    assert rule.update(0.0001, achieved=None) == pytest.approx(0.6 * pacing.SPEED_UP_FACTOR)   # calm again


def test_auto_with_a_target_above_real_time_stays_under_it():
    rule = AutoSpeed(target=2.0)
    for _ in range(10):
        rule.update(0.0)
    assert rule.speed == 2.0
    # at 2x, 1.5 ms of wall lateness is 3 ms of world time: too late
    assert rule.update(0.0015) < 2.0


class _Schedstats:
    """Made-up schedstat readings: pid -> (ns run, ns waited, slices), advanced by the test."""

    def __init__(self) -> None:
        self.stats = {}
        self.asked = []

    def read(self, pids):
        self.asked.append(list(pids))
        return {p: self.stats[p] for p in pids if p in self.stats}


def test_host_delay_is_the_mean_wait_per_time_slice_of_the_processes_seen_twice():
    fake, t = _Schedstats(), [0.0]
    host = HostDelay(pids=lambda: [10, 11, 12], read=fake.read, now=lambda: t[0])
    fake.stats = {10: (0, 0, 0), 11: (0, 0, 0)}
    assert host.sample() is None                                      # nothing to compare with yet
    fake.stats = {10: (5_000_000, 2_000_000, 100), 11: (1_000_000, 1_000_000, 50), 12: (9, 9_000_000, 1)}
    assert host.sample() == pytest.approx(3e-3 / 150)                 # 12 is new: not counted
    assert host.processes == 3
    fake.stats = {10: (5_000_000, 2_000_000, 100), 12: (9, 9_000_000, 1)}
    assert host.sample() is None                                      # none ran: nothing to judge
    t[0] = 100.0
    host.sample()
    assert len(fake.asked) == 4                                       # the pids are re-read after a while


def test_schedstat_of_this_process_and_its_siblings_can_be_read():
    own = read_schedstat([os.getpid()])
    assert own[os.getpid()][0] > 0 and own[os.getpid()][2] > 0
    assert read_schedstat([2 ** 22 + 12345]) == {}                    # a process that is gone is left out
    assert os.getpid() not in sibling_pids()
    node = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(10)"])     # a node of the launch
    try:
        world = subprocess.run([sys.executable, "-c", "from crazyflie_driver.sim.room.pacing import sibling_pids; "
                                "print(sibling_pids())"],
                               capture_output=True, text=True, timeout=20)
        assert node.pid in eval(world.stdout)          # the world sees the launch's other node as host
    finally:
        node.kill()
        node.wait()


def test_a_speed_change_continues_world_time_without_a_jump():
    """After set_speed(0.25) the world's schedule runs at a quarter of real time from where it was: 50 ms
    of world time take at least 200 ms of wall time (a busy machine only makes it longer), and every
    tick is stepped once (no jump, no repeat)."""
    w = World(speed=1.0, seed=1)
    w.add_vehicle("cf1")
    seen = []
    w.add_tick_listener(lambda now: seen.append(now), 0.001)
    w.start()
    try:
        assert wait_for(lambda: w.time >= 0.05, 10.0)
        w.set_speed(0.25)
        assert wait_for(lambda: w.wall_time_of(1.0) is not None and w.speed == 0.25, 1.0)
        t0, wall0 = w.time, time.monotonic()
        assert wait_for(lambda: w.time >= t0 + 0.05, 10.0)
        wall = time.monotonic() - wall0
    finally:
        w.stop()
    assert wall >= 0.05 / 0.25 - 0.01
    steps = [b - a for a, b in zip(seen, seen[1:])]
    assert max(steps) == pytest.approx(0.001, abs=1e-9) and min(steps) == pytest.approx(0.001, abs=1e-9)
    with pytest.raises(ValueError, match="speed"):
        w.set_speed(-1.0)


def wait_for(cond, seconds: float) -> bool:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.002)
    return bool(cond())


class _World:
    """What the pacer needs of a world: its measured factor, its speed, ``set_speed``."""

    def __init__(self) -> None:
        self.realtime_factor = 1.0
        self.speed = 1.0
        self.overruns = 0
        self.ticks_behind = 0
        self.set_to = []

    def set_speed(self, speed: float) -> None:
        self.speed = speed
        self.set_to.append(speed)


class _Host:
    def __init__(self) -> None:
        self.lag = None

    def sample(self):
        return self.lag


def test_pacer_sets_the_world_speed_from_the_host_waits():
    world, host = _World(), _Host()
    pacer = pacing.AutoPacer(world, Pacing(True, 1.0), host)
    pacer.step()                            # nothing to judge: nothing changes
    host.lag = 0.0001
    pacer.step()                            # calm
    assert world.set_to == []
    host.lag = 0.004
    pacer.step()                            # 4 ms of wait in world time: halved
    assert world.set_to == [pytest.approx(0.5)]
    assert pacer.lag_wall_s == 0.004 and pacer.samples == 2
    assert pacing.start_pacing(world, Pacing(False, 1.0)) is None     # a fixed speed needs no pacer


def test_pacer_takes_the_achieved_factor_only_when_the_world_is_behind_its_own_schedule():
    """A factor measured partly at the previous speed does not veto a speed-up; a world that overran does."""
    world, host = _World(), _Host()
    host.lag = 0.0001
    pacer = pacing.AutoPacer(world, Pacing(True, 1.0), host)
    world.realtime_factor = 0.6          # stale: the last second ran partly at an older speed
    pacer.step()
    assert world.set_to == []
    world.overruns = 1                   # the world let go of a lag: it cannot keep 1.0
    pacer.step()
    assert world.set_to == [pytest.approx(0.6)]
    world.realtime_factor = 0.3
    world.ticks_behind = pacing.BEHIND_TICKS + 1
    pacer.step()
    assert world.set_to[-1] == pytest.approx(0.3)


def test_a_started_pacer_stops():
    world, host = _World(), _Host()
    pacer = pacing.AutoPacer(world, Pacing(True, 1.0), host).start()
    pacer.stop()
    assert not pacer._thread.is_alive()


def _stalled_world(max_lag_s: float):
    """A world at real time whose thread is held up 150 ms of wall time once, at world time 50 ms;
    the ticks it steps back to back after the stall, and its overrun count."""
    w = World(speed=1.0, seed=1)
    w.add_vehicle("cf1")
    w.max_lag_s = max_lag_s
    stalled = []

    def stall(now: float) -> None:
        if now >= 0.05 and not stalled:
            stalled.append(now)
            time.sleep(0.15)
    w.add_tick_listener(stall, 0.001)
    steps = []
    step = w.step

    def recording_step(n: int = 1) -> None:
        steps.append((stalled[:], n))
        step(n)
    w.step = recording_step            # the thread's calls, each with whether the stall had happened
    w.start()
    try:
        assert wait_for(lambda: w.time >= 0.3, 10.0)
    finally:
        w.stop()
    after = [n for was, n in steps if was]
    return after, w.overruns


def test_an_auto_world_held_up_starts_a_new_schedule_instead_of_bursting():
    """150 ms late, a world that catches up would step 150 ticks back to back (world time racing
    the host); an auto world lets go: its next step is one wake-up's worth, and it counts an overrun."""
    after, overruns = _stalled_world(pacing.AUTO_MAX_LAG_S)
    assert after[0] == round(world_module.WAKE_PERIOD_S / FIRMWARE_TICK_S) and overruns >= 1, after[:5]
    after, _ = _stalled_world(0.25)             # a fixed-speed world catches up, 20 ticks at a time
    assert after[0] == world_module.MAX_CHUNK_TICKS, after[:5]
