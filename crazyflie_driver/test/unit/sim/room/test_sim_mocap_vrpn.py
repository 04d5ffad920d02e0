"""The world's motion capture as a VRPN server: the stack's own VRPN client reads one tracker per
vehicle with the mocap model's poses; a body the model loses is not sent."""
from __future__ import annotations

import contextlib
import os
import pathlib
import signal
import subprocess
import sys
import threading
import time
from typing import Iterator, List, Tuple

import numpy as np

from crazyflie_driver.mocap.vrpn_client import VrpnClient
from crazyflie_driver.sim.room.mocap import MocapModel
from crazyflie_driver.sim.room.mocap_vrpn import WorldVrpnServer, port_is_free
from crazyflie_driver.sim.room.world import World

SRC = pathlib.Path(__file__).resolve().parents[4] / "src"


def wait_until(cond, timeout=5.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.01)
    return cond()


class Reports:
    """What the client received: (world time at receipt [s], the server's stamp [s]) per report."""

    def __init__(self, world: World) -> None:
        self.world = world
        self._rows: List[Tuple[float, float]] = []
        self._lock = threading.Lock()

    def on_pose(self, report) -> None:
        with self._lock:
            self._rows.append((float(self.world.time), report.server_sec + report.server_usec * 1e-6))

    def rows(self) -> List[Tuple[float, float]]:
        with self._lock:
            return list(self._rows)

    def stamps(self) -> List[float]:
        return [s for _, s in self.rows()]

    def __len__(self) -> int:
        with self._lock:
            return len(self._rows)


@contextlib.contextmanager
def vrpn_stream(world: World, mocap: MocapModel) -> Iterator[Reports]:
    """The world running and serving its motion capture over VRPN, the stack's client reading it."""
    reports = Reports(world)
    server = WorldVrpnServer(world, mocap, port=0)
    world.start()
    try:
        server.start()
        with VrpnClient("127.0.0.1", server.port, on_pose=reports.on_pose, retry_min=0.1, retry_max=0.4):
            yield reports
    finally:
        server.stop()
        world.stop()


def test_one_tracker_per_vehicle_with_the_mocap_model_poses():
    world = World(speed=1.0, seed=4)
    world.add_vehicle("cf1", position=(0.5, -0.25, 0.0))
    world.add_vehicle("cf2", position=(-1.0, 2.0, 0.0), yaw=1.0)
    mocap = MocapModel(world, rate=100.0, seed=4).attach()
    poses, lock = [], threading.Lock()

    def on_pose(report):
        with lock:
            poses.append(report)

    def of(name):
        with lock:
            return [p for p in poses if p.tracker == name]

    server = WorldVrpnServer(world, mocap, port=0)
    world.start()
    try:
        server.start()
        assert server.port > 0
        with VrpnClient("127.0.0.1", server.port, on_pose=on_pose, retry_min=0.1, retry_max=0.4):
            assert wait_until(lambda: len(of("cf1")) > 20 and len(of("cf2")) > 20)
            p2 = of("cf2")[-1]
            assert np.allclose(p2.position, (-1.0, 2.0, 0.0), atol=0.003)
            assert abs(p2.orientation[2] - np.sin(0.5)) < 0.01              # yaw 1 rad
            mocap.set_visible("cf1", False)                                   # the body is lost
            mark = len(of("cf2"))
            assert wait_until(lambda: len(of("cf2")) > mark + 10)            # the hiding has taken effect
            before, mark = len(of("cf1")), len(of("cf2"))
            assert wait_until(lambda: len(of("cf2")) > mark + 30)
            assert len(of("cf1")) == before                                  # nothing for the lost body
    finally:
        server.stop()
        world.stop()


def test_default_port_is_3883_when_free_else_another():
    world = World(speed=0)
    mocap = MocapModel(world)
    free = port_is_free("127.0.0.1", 3883)
    first = WorldVrpnServer(world, mocap)
    first.start()
    try:
        second = WorldVrpnServer(world, mocap)
        second.start()
        try:
            assert (first.port == 3883) == free                      # the VRPN default when nobody has it
            assert second.port not in (first.port, 3883)
        finally:
            second.stop()
    finally:
        first.stop()


def test_each_delivered_frame_is_sent_once_with_the_model_rate_and_dropouts():
    """Reports follow the model's frames, not a timer of their own: 100 Hz of world time, 30 % of the
    body's frames lost, no frame sent twice, stamps on the capture times' 10 ms grid."""
    world = World(speed=1.0, seed=7)
    world.add_vehicle("cf1", position=(0.0, 0.0, 0.0))
    mocap = MocapModel(world, rate=100.0, dropout=0.3, latency=0.02, seed=7).attach()
    with vrpn_stream(world, mocap) as got:
        assert wait_until(lambda: len(got) > 150, timeout=20.0)
    reports = got.rows()
    world_span = reports[-1][0] - reports[0][0]
    fraction = (len(reports) - 1) / (world_span * 100.0)
    assert 0.6 < fraction < 0.8, fraction                 # 70 % of the captures arrive
    stamps = [s for _, s in reports]
    steps = np.diff(stamps)
    assert (steps > 0.005).all()                          # never the same capture twice
    # the stamps sit on the 10 ms capture grid (up to the host's jitter in mapping world to wall time)
    ticks = steps / 0.01
    assert np.median(np.abs(ticks - np.round(ticks))) < 0.2


def test_frames_of_a_catch_up_burst_keep_their_capture_spacing():
    """A world that fell behind (here its stepping thread stalls 80 ms) steps the missed ticks in one
    go; the frames of that burst are stamped by the world's schedule, a frame period apart, not
    crowded at their delivery time."""
    world = World(speed=1.0, seed=3)
    world.add_vehicle("cf1", position=(0.0, 0.0, 0.0))
    mocap = MocapModel(world, rate=100.0, seed=3).attach()
    stalls = []

    def stall(world_t):
        if not stalls:
            stalls.append(world_t)
            time.sleep(0.08)
    with vrpn_stream(world, mocap) as got:
        assert wait_until(lambda: len(got) > 5, timeout=10.0)
        world.add_tick_listener(stall, period=10.0, first=world.time + 0.2)
        assert wait_until(lambda: stalls and len(got) > 60, timeout=10.0)
    steps = np.diff(got.stamps())
    off_grid = steps[np.abs(steps - 0.01) >= 0.001]
    assert len(off_grid) <= world.overruns, np.round(off_grid, 4)     # a world that let go starts a new schedule


def test_stamps_never_go_back_when_the_worlds_schedule_changes():
    """An auto-paced world changes its speed and starts new schedules; a capture made under the old
    schedule and delivered under the new one can map to an earlier host time than the capture sent
    before it (here the schedule jumps 0.5 s back and forth every 50 ms of world time). The stamps still
    strictly increase, as a motion-capture system's do."""
    world = World(speed=1.0, seed=3)
    world.add_vehicle("cf1", position=(0.0, 0.0, 0.0))
    mocap = MocapModel(world, rate=100.0, seed=3).attach()
    scheduled = world.wall_time_of
    world.wall_time_of = lambda t: (lambda w: None if w is None else w - 0.5 * (int(t * 20) % 2))(scheduled(t))
    with vrpn_stream(world, mocap) as got:
        assert wait_until(lambda: len(got) > 40, timeout=10.0)
    stamps = got.stamps()
    steps = np.diff(stamps)
    assert (steps > 0).all(), (steps.min(), np.argmin(steps), stamps[:3])
    assert (steps < 1e-5).any()                # captures mapped back were held just after the one before


def test_world_server_command_line_places_a_swarm_file_and_serves_vrpn():
    """``crazyflie_world_server --swarm FILE --vrpn PORT``: the swarm file's Crazyflies on the URIs the
    server derives (one dongle per channel), at their initial positions, one VRPN tracker each."""
    from crazyflie_driver.sim.air.medium import RemoteMedium
    env = dict(os.environ, PYTHONPATH=str(SRC) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    swarm = SRC.parent / "config" / "swarm_example.yaml"          # ids 1, 2 on channel 80, id 3 on 90
    proc = subprocess.Popen([sys.executable, str(SRC.parent / "scripts" / "crazyflie_world_server"),
                             "--address", "127.0.0.1:0", "--swarm", str(swarm), "--vrpn", "0", "--mocap-noise", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    poses, lock = {}, threading.Lock()

    def on_pose(report):
        with lock:
            poses[report.tracker] = report.position

    try:
        lines = []
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and proc.poll() is None and not any("world served on" in ln for ln in lines):
            lines.append(proc.stderr.readline())
        served = [ln for ln in lines if "served as VRPN on 127.0.0.1:" in ln]
        assert served, lines
        port = int(served[0].split("127.0.0.1:")[1].split()[0])
        world_port = int([ln for ln in lines if "world served on" in ln][0].split("127.0.0.1:")[1].split()[0])
        medium = RemoteMedium("127.0.0.1", world_port)
        try:
            assert medium.dongle_count() == 2
            listed = {e["name"]: e["uri"] for e in medium.control("list")}
        finally:
            medium.close()
        assert listed == {"cf1": "radio://0/80/2M/E7E7E7E701", "cf2": "radio://0/80/2M/E7E7E7E702",
                          "cf3": "radio://1/90/2M/E7E7E7E703"}
        with VrpnClient("127.0.0.1", port, on_pose=on_pose, retry_min=0.1, retry_max=0.4):
            assert wait_until(lambda: len(poses) == 3, timeout=10.0)
        for name, where in (("cf1", (0.0, 0.0, 0.0)), ("cf2", (0.5, 0.0, 0.0)), ("cf3", (0.0, 0.5, 0.0))):
            assert np.allclose(poses[name], where, atol=1e-6), name
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_world_server_refuses_a_bad_swarm_file(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(SRC) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    bad = tmp_path / "swarm.yaml"
    bad.write_text("crazyflies:\n  - {id: 1, channel: 80}\n  - {id: 1, channel: 80}\n")
    done = subprocess.run([sys.executable, str(SRC.parent / "scripts" / "crazyflie_world_server"),
                           "--address", "127.0.0.1:0", "--swarm", str(bad)], env=env, capture_output=True, text=True,
                          timeout=30)
    assert done.returncode == 2
    assert "id 1 is already used" in done.stderr and "swarm.yaml:3" in done.stderr


def test_world_server_refuses_a_busy_vrpn_port(capsys):
    import socket

    from crazyflie_driver.sim.world_server import main
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(1)
    try:
        assert main(["--uri", "radio://0/80/2M/E7E7E7E701", "--address", "127.0.0.1:0",
                     "--vrpn", str(s.getsockname()[1])]) == 2
    finally:
        s.close()
    assert "cannot serve VRPN on port" in capsys.readouterr().err
