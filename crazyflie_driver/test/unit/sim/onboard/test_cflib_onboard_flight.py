"""Bitcraze's cflib 0.1.34, unmodified, flies the simulated Crazyflie the current way: motion capture
streamed to the onboard estimator (extpos / extpose at 100 Hz), onboard PID position control,
position, hover and velocity-world setpoints; and the complementary-estimator trap.

A world server runs in this process (ephemeral ports); ``support/cflib_onboard_session.py`` runs in
cflib's own interpreter over the fake Crazyradio or udp://. The flight is judged on the world's true
positions, which the session samples through the server's control API. The session counts its
durations in world seconds and the world runs at ``auto`` speed, paced by the session's waits for a
CPU (as a launch's world is paced by its nodes'), so a busy machine slows the flight, not worsens it.
"""
from __future__ import annotations

import json
import math
import os
import pathlib
import subprocess
from typing import List

import pytest

from crazyflie_driver.sim.room.pacing import AutoPacer, HostDelay, Pacing
from crazyflie_driver.sim.world_server import WorldServer
from support.cflib_python import cflib_python

TEST = pathlib.Path(__file__).resolve().parents[3]
SESSION = TEST / "support" / "cflib_onboard_session.py"
SRC = TEST.parent / "src"
URI_HOLD = "radio://0/80/2M/E7E7E7E703"          # starts at the origin
URI_TRAP = "radio://0/80/2M/E7E7E7E704"          # starts away from the origin
TRAP_START = (1.0, 0.5)
SESSION_TIMEOUT_S = 45.0
SESSIONS: List[int] = []     # pids of the running cflib sessions: the host the world is paced by


@pytest.fixture(scope="module")
def python():
    return cflib_python()


@pytest.fixture(scope="module")
def served():
    from crazyflie_driver.sim.room.world import World
    world = World(speed=1.0, seed=5)
    server = WorldServer(world, dongles=2, port=0, seed=5, udp_base_port=0)   # cflib's and a broadcaster
    server.add_crazyflie(URI_HOLD, "cf3", (0.0, 0.0, 0.0), "current")
    server.add_crazyflie(URI_TRAP, "cf4", (TRAP_START[0], TRAP_START[1], 0.0), "current")
    server.start()
    world.start()
    pacer = AutoPacer(world, Pacing(True, 1.0), HostDelay(pids=lambda: list(SESSIONS), refresh_s=0.0)).start()
    yield server
    pacer.stop()
    server.stop()
    world.stop()


def fly(python, server, uri, sim_uri, *args):
    env = dict(os.environ)
    env.update(PYTHONPATH=os.pathsep.join((str(SRC), str(TEST))), CRAZYFLIE_SIM_ADDRESS=server.address,
               PYTHONUNBUFFERED="1")
    env.pop("CRAZYFLIE_BACKEND", None)
    cmd = [python, str(SESSION), "--uri", uri, "--sim-uri", sim_uri, "--timeout", str(SESSION_TIMEOUT_S)] + list(args)
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    SESSIONS.append(proc.pid)
    try:
        stdout, stderr = proc.communicate(timeout=SESSION_TIMEOUT_S + 15)
    finally:
        SESSIONS.remove(proc.pid)
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    lines = [line for line in stdout.splitlines() if line.startswith("{")]
    assert lines, "no JSON from the cflib session (exit %d)\nstderr:\n%s" % (proc.returncode, stderr[-3000:])
    result = json.loads(lines[-1])
    assert proc.returncode == 0 and result["error"] is None, \
        "cflib session failed: %s\nstderr:\n%s" % (result["error"], stderr[-3000:])
    return result


def settle(server, uri):
    """Back on the floor, motors off, firmware rebooted: the next flight starts from rest."""
    server.crazyflie(uri).reboot()
    name = [e for e in server.entries() if e.uri == uri][0].name
    vehicle = server.world.vehicle(name)
    start = vehicle.state()["position"]
    vehicle.place((start[0], start[1], 0.0))


def last_seconds(samples, seconds):
    t_end = samples[-1][0]
    return [s for s in samples if s[0] >= t_end - seconds]


def distance(sample, goal):
    return math.sqrt(sum((a - b) ** 2 for a, b in zip(sample[1:4], goal)))


@pytest.mark.parametrize("link,pose", [("radio", False), ("udp", True)])
def test_cflib_streams_mocap_and_flies_onboard_setpoints(python, served, link, pose):
    entry = [e for e in served.entries() if e.uri == URI_HOLD][0]
    uri = URI_HOLD if link == "radio" else entry.udp.uri
    args = ["--pose"] if pose else []
    r = fly(python, served, uri, URI_HOLD, *args)
    settle(served, URI_HOLD)
    assert r["params"] == {"stabilizer.estimator": "2", "stabilizer.controller": "1"}
    phases = r["phases"]
    # 100 Hz motion capture for the whole flight (counted on the world's clock)
    world_span = phases["after_stop"][-1][0] - phases["position"][0][0]
    assert r["extpos_sent"] >= 0.7 * 100 * world_span
    # position setpoint (0, 0, 0.5): holds it at the end of the phase
    hold = last_seconds(phases["position"], 1.5)
    assert max(distance(s, (0.0, 0.0, 0.5)) for s in hold) < 0.06, hold[-1]
    # hover at 0.5 m with zero velocity: stays there
    assert all(abs(s[3] - 0.5) < 0.08 for s in phases["hover"])
    # velocity world 0.3 m/s along x for 2 s: moves about 0.6 m in x, keeps y and z
    v = phases["velocity"]
    moved = v[-1][1] - v[0][1]
    assert 0.35 < moved < 0.85 and abs(v[-1][2] - v[0][2]) < 0.15 and abs(v[-1][3] - 0.5) < 0.15
    # notify-setpoint-stop with no high-level plan: the motors stop
    assert phases["after_stop"][-1][4] == 0.0


def test_cflib_complementary_estimator_trap(python, served):
    """Estimator 1 ignores extpos: the position setpoint at the start point is chased against an
    estimate that stays at x = y = 0, so the Crazyflie leaves instead of hovering."""
    goal = (TRAP_START[0], TRAP_START[1], 0.5)
    r = fly(python, served, URI_TRAP, URI_TRAP, "--estimator", "1", "--trap", "--seconds", "3",
            "--goal", *[str(g) for g in goal])
    settle(served, URI_TRAP)
    assert r["params"]["stabilizer.estimator"] == "1"
    end = r["phases"]["position"][-1]
    assert distance(end, goal) > 0.8 and abs(end[3] - 0.5) < 0.2


def test_cflib_high_level_takeoff_go_to_figure_eight_and_land(python, served, tmp_path):
    """The done-when flight: extpos at 100 Hz, estimator 2 + controller 1, HL takeoff, go_to, a
    figure-8 uploaded through cflib's trajectory memory API (Poly4D, write_data_sync), defined,
    started, and a landing; the path is checked on the world's true state."""
    from crazyflie_driver.sim.onboard.planner import Plan, figure_eight
    pieces = figure_eight(0.6, 0.3, 8.0, 8, 0.5)
    spec = tmp_path / "figure8.json"
    spec.write_text(json.dumps([{"duration": p.duration, "x": list(p.coeffs[0]), "y": list(p.coeffs[1]),
                                 "z": list(p.coeffs[2]), "yaw": list(p.coeffs[3])} for p in pieces]))
    r = fly(python, served, URI_HOLD, URI_HOLD, "--high-level", str(spec))
    settle(served, URI_HOLD)
    assert r["upload_ok"] is True
    ph = r["phases"]
    assert abs(ph["takeoff"][-1][3] - 0.5) < 0.05 and ph["takeoff"][-1][4] > 0
    assert distance(ph["go_to"][-1], (0.3, 0.2, 0.6)) < 0.05
    assert distance(ph["back"][-1], (0.0, 0.0, 0.5)) < 0.05
    # the curve from the world time the firmware began it (the start command may arrive late)
    begin = r["trajectory_begin"]
    assert r["trajectory_start"] <= begin
    plan = Plan(1, pieces, begin)
    flown = [s for s in ph["trajectory"] if s[0] <= begin + plan.duration]
    errors = [distance(s, plan.evaluate(s[0]).pos) for s in flown]
    xs, ys = [s[1] for s in flown], [s[2] for s in flown]
    # the figure is flown (both lobes, full width), with the PID controller's lag (no feed-forward)
    assert max(xs) > 0.4 and min(xs) < -0.4 and max(ys) > 0.15 and min(ys) < -0.15
    assert sum(errors) / len(errors) < 0.3
    assert distance(ph["trajectory"][-1], (0.0, 0.0, 0.5)) < 0.08          # the end point is held
    assert ph["land"][-1][3] < 0.03 and ph["land"][-1][4] == 0.0            # landed, motors off


def test_cflib_mellinger_compressed_trajectory_driven_by_broadcasts(python, served, tmp_path):
    """Controller 2 (Mellinger) with extpos from cflib; a figure-8 uploaded with cflib's compressed
    classes and defined as compressed; cflib's takeoff; the trajectory's start and the landing sent
    to the broadcast address (group 1) by our BroadcastLink. The other Crazyflie on the channel (group
    0) stays on the floor; the path is checked on the world's true state against the curve."""
    from crazyflie_driver.protocol.trajectory import bezier_points
    from crazyflie_driver.sim.onboard.planner import Plan, figure_eight
    pieces = figure_eight(0.5, 0.25, 6.0, 6, 0.5)
    segments = [[p.duration] + [bezier_points(p.coeffs[axis], p.duration)[1:] for axis in range(4)] for p in pieces]
    spec = tmp_path / "compressed.json"
    spec.write_text(json.dumps({"start": [0.0, 0.0, 0.5, 0.0], "segments": segments}))
    other = served.world.vehicle([e for e in served.entries() if e.uri == URI_TRAP][0].name)
    r = fly(python, served, URI_HOLD, URI_HOLD, "--controller", "2", "--compressed", str(spec))
    other_state = other.state()
    settle(served, URI_HOLD)
    assert r["upload_ok"] is True
    assert r["params"] == {"stabilizer.estimator": "2", "stabilizer.controller": "2", "hlCommander.groupmask": "1"}
    ph = r["phases"]
    assert abs(ph["takeoff"][-1][3] - 0.5) < 0.05
    # the curve from the world time the firmware began it (the broadcast may arrive late)
    begin = r["trajectory_begin"]
    assert r["trajectory_start"] <= begin
    plan = Plan(1, pieces, begin)
    flown = [s for s in ph["trajectory"] if begin + 1.0 <= s[0] <= begin + 6.0]
    errors = [distance(s, plan.evaluate(s[0]).pos) for s in flown]
    xs, ys = [s[1] for s in flown], [s[2] for s in flown]
    # Mellinger with the plan's feed-forward: close tracking (the PID flight above lags by ~0.2 m)
    assert max(xs) > 0.4 and min(xs) < -0.4 and max(ys) > 0.2 and min(ys) < -0.2
    assert sum(errors) / len(errors) < 0.06
    assert ph["land"][-1][3] < 0.03 and ph["land"][-1][4] == 0.0            # the broadcast landing
    assert other_state["position"][2] < 0.02 and max(other_state["motors"]) == 0   # not in group 1
    assert served.crazyflie(URI_TRAP).snapshot()["rx_broadcast"] > 0              # ... though it heard them
