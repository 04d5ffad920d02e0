"""Bitcraze's cflib as the peer: is our fake Crazyradio and simulated Crazyflie real enough for it?

A world server runs in this process (ephemeral TCP port, UDP endpoints on ephemeral ports) with two
simulated Crazyflies: radio://0/80/2M/E7E7E7E701 (current firmware) and ...02 (2016.02 firmware,
V1 TOCs). ``support/cflib_session.py`` runs in cflib's own virtual environment (created by
``tools/bootstrap.sh --with-cflib``), wraps ``usb.core.find`` so cflib's Crazyradio driver lands on our
fake dongle, and drives a whole session with cflib's API. The tests check cflib's report and what
the simulated Crazyflie saw.
"""
from __future__ import annotations

import json
import math
import os
import pathlib
import subprocess

import pytest

from crazyflie_driver.sim.world_server import WorldServer
from support.cflib_python import cflib_python

TEST = pathlib.Path(__file__).resolve().parents[2]        # crazyflie_driver/test
SRC = TEST.parent / "src"
SESSION = TEST / "support" / "cflib_session.py"
URI1 = "radio://0/80/2M/E7E7E7E701"
URI2 = "radio://0/80/2M/E7E7E7E702"
SESSION_TIMEOUT_S = 25.0


def make_world():
    from crazyflie_driver.sim.room.world import World
    return World(speed=1.0, seed=7)


@pytest.fixture(scope="module")
def python():
    return cflib_python()


@pytest.fixture(scope="module")
def served():
    world = make_world()
    server = WorldServer(world, dongles=1, port=0, seed=7, udp_base_port=0)
    server.add_crazyflie(URI1, "cf1", (0.0, 0.0, 0.0), "current")
    server.add_crazyflie(URI2, "cf2", (0.5, 0.0, 0.0), "2016.02")
    server.start()
    world.start()
    yield server
    server.stop()
    world.stop()


def run_session(python, server, uri, *args):
    env = dict(os.environ)
    env.update(PYTHONPATH=os.pathsep.join((str(SRC), str(TEST))), CRAZYFLIE_SIM_ADDRESS=server.address,
               PYTHONUNBUFFERED="1")
    env.pop("CRAZYFLIE_BACKEND", None)
    cmd = [python, str(SESSION), "--uri", uri, "--timeout", str(SESSION_TIMEOUT_S)] + list(args)
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=SESSION_TIMEOUT_S + 10)
    lines = [line for line in proc.stdout.splitlines() if line.startswith("{")]
    assert lines, "no JSON from the cflib session (exit %d)\nstderr:\n%s" % (proc.returncode, proc.stderr[-3000:])
    result = json.loads(lines[-1])
    assert proc.returncode == 0 and result["error"] is None, \
        "cflib session failed: %s\nstderr:\n%s" % (result["error"], proc.stderr[-3000:])
    return result


#: A current-firmware session also logs a variable past id 255 of the real-size table, one the world drives.
LOG_FAR = "acc.z,pm.vbat,stateEstimate.qw"


def check_session(result, sim, param, written, period_ms, log_vars=("acc.z", "pm.vbat")):
    """What every session must show, from cflib's side and from the simulated Crazyflie's side."""
    # Both TOCs, with the counts the simulated firmware serves.
    assert result["connected"] is True
    assert result["log_toc_count"] == len(sim.logs.entries) > 20
    assert result["param_toc_count"] == len(sim.params.entries) > 20
    assert "acc.z" in result["log_toc_names"] and "pm.vbat" in result["log_toc_names"]
    # Every parameter value read, equal to what the firmware holds (cflib keeps them as text).
    params = result["params"]
    assert len(params) == len(sim.params.entries)
    for i, entry in enumerate(sim.params.entries):
        if entry.full_name == param:
            continue
        held = sim.params.values[i]
        got = float(params[entry.full_name])
        assert math.isclose(got, held, rel_tol=1e-6, abs_tol=1e-6), (entry.full_name, got, held)
    assert int(float(params["cpu.flash"])) == 1024
    # The write is echoed, read back from the Crazyflie, and changed inside the simulation.
    w = result["param_write"]
    assert w["before"] != written and w["echoed"] == written and w["read_back"] == written
    assert sim.params.values[sim.params.ident(param)] == int(written)
    # The log block at its period, with a Crazyflie standing still on the ground.
    log = result["log"]
    stamps = log["timestamps"]
    # Samples for the world time between START and STOP (world time, not the host's clock: the
    # world steps in real time on average but catches up in bursts after a lag).
    expected = log["world_seconds"] * 1000.0 / period_ms
    assert len(stamps) >= 3 and 0.6 * expected <= len(stamps) <= expected + 2, (len(stamps), expected)
    # Onboard timestamps: each step is the period up to the 1 ms tick of the firmware timer, and
    # the timer does not drift (the world steps in real time from a thread, so a tick can be late).
    steps = [b - a for a, b in zip(stamps, stamps[1:])]
    assert all(abs(s - period_ms) <= 2 for s in steps), "onboard timestamps step by %s ms, period %d ms" \
        % (sorted(set(steps)), period_ms)
    assert abs((stamps[-1] - stamps[0]) / float(len(steps)) - period_ms) <= 1.0, steps
    for values in log["values"]:
        assert abs(values["acc.z"] - 1.0) < 0.05, values
        assert 3.7 <= values["pm.vbat"] <= 4.2, values
        if "stateEstimate.qw" in log_vars:      # the estimator's live attitude: level, not a constant 0
            assert abs(values["stateEstimate.qw"] - 1.0) < 0.01, values
    # Setpoints reached the commander (seen through the control API from cflib's process):
    # roll as sent, pitch negated by cflib (legacy frame), yaw rate and thrust as sent.
    seen = result["sim_state"]
    assert seen["last_setpoint"] == [1.5, -2.5, -3.0, 12000]
    assert seen["setpoints"] >= result["setpoints_sent"]
    assert seen["params"][param] == int(written)
    assert [b["variables"] for b in seen["log_blocks"].values()] == [list(log_vars)]
    assert sim.state.setpoints >= result["setpoints_sent"]
    # cflib's disconnect was clean.
    assert result["disconnected"] is True


def check_real_size(s, sim, param):
    """The current firmware's real-size TOCs, listed whole by cflib; the parameter and a log variable past id 255."""
    assert len(sim.params.entries) > 380 and len(sim.logs.entries) > 580
    assert s["param_toc_count"] == len(sim.params.entries) and s["log_toc_count"] == len(sim.logs.entries)
    assert sim.params.ident(param) > 255
    assert [e.full_name for e in sim.logs.entries].index("stateEstimate.qw") > 255


def test_cflib_radio_session_current_firmware(python, served):
    sim = served.crazyflie(URI1)
    before = dict(sim.state.packets_by_port)
    r = run_session(python, served, URI1, "--scan-address", "E7E7E7E701", "--param", "hlCommander.groupmask=3",
                    "--log", LOG_FAR, "--log-seconds", "1.0", "--period-ms", "50", "--sim-name", "cf1")
    assert "radio://0/80/2M/E7E7E7E701" in r["scan"]
    assert not any(u.startswith("radio://") and not u.startswith("radio://0/80/2M/") for u in r["scan"])
    s = r["sessions"][URI1]
    assert s["protocol_version"] == 12
    assert s["link_needs_resending"] is False          # safelink was negotiated with the nRF side
    assert r["dongle"]["bulk_out"] > 300 and r["dongle"]["control_transfers"] > 300   # scan + session
    check_real_size(s, sim, "hlCommander.groupmask")
    check_session(s, sim, "hlCommander.groupmask", "3", 50, LOG_FAR.split(","))
    assert sim.state.packets_by_port.get(3, 0) - before.get(3, 0) >= s["setpoints_sent"]


def test_cflib_radio_session_2016_firmware(python, served):
    sim = served.crazyflie(URI2)
    r = run_session(python, served, URI2, "--param", "ring.solidRed=33", "--log-seconds", "0.6",
                    "--period-ms", "20", "--sim-name", "cf2")
    s = r["sessions"][URI2]
    assert s["protocol_version"] == 2
    check_session(s, sim, "ring.solidRed", "33", 20)
    # The boot text waited in the TX queue for the first host, as on the real firmware.
    assert "SYS: Crazyflie 2.0 is up and running!\n" in s["console"]


def test_cflib_two_crazyflies_on_one_dongle(python, served):
    """cflib's own dongle sharing: both generations connected and logging at the same time."""
    r = run_session(python, served, URI1, "--uri", URI2, "--param", "ring.solidGreen=44",
                    "--param", "ring.solidGreen=55", "--sim-name", "cf1", "--sim-name", "cf2",
                    "--log-seconds", "0.6", "--period-ms", "30")
    assert r["sessions"][URI1]["protocol_version"] == 12 and r["sessions"][URI2]["protocol_version"] == 2
    check_session(r["sessions"][URI1], served.crazyflie(URI1), "ring.solidGreen", "44", 30)
    check_session(r["sessions"][URI2], served.crazyflie(URI2), "ring.solidGreen", "55", 30)
    # Interleaved round trips re-address the dongle (SET_RADIO_ADDRESS) many times.
    assert r["dongle"]["control_transfers"] > 100


def test_cflib_udp_session(python, served):
    entry = [e for e in served.entries() if e.uri == URI1][0]
    sim = entry.crazyflie
    r = run_session(python, served, entry.udp.uri, "--param", "sound.freq=4400", "--log", LOG_FAR,
                    "--log-seconds", "0.5", "--period-ms", "100", "--sim-name", "cf1")
    s = r["sessions"][entry.udp.uri]
    assert s["protocol_version"] == 12
    assert entry.udp.datagrams_in > s["param_toc_count"] + s["log_toc_count"]
    check_real_size(s, sim, "sound.freq")
    check_session(s, sim, "sound.freq", "4400", 100, LOG_FAR.split(","))


def test_cflib_safelink_over_a_lossy_radio(python, served):
    """cflib's safelink against the simulated nRF's, with 20 % of packets and 20 % of acks lost:
    cflib never re-sends requests on a safelink link, so any duplicate or lost downlink stalls it,
    and any duplicated uplink shows up as an extra setpoint in the commander."""
    sim = served.crazyflie(URI1)
    setpoints_before = sim.state.setpoints
    served.medium.set_dongle_faults(0, packet_loss=20.0, ack_loss=20.0)
    try:
        r = run_session(python, served, URI1, "--param", "radiotest.power=-7", "--log-seconds", "0.5",
                        "--period-ms", "20", "--sim-name", "cf1")
    finally:
        served.medium.set_dongle_faults(0, packet_loss=0.0, ack_loss=0.0)
    s = r["sessions"][URI1]
    assert s["link_needs_resending"] is False
    check_session(s, sim, "radiotest.power", "-7", 20)
    assert s["sim_state"]["setpoints"] - setpoints_before == s["setpoints_sent"]   # each delivered once
    assert sim.link.duplicates > 0                      # lost acks made cflib repeat packets
