#!/usr/bin/env python3
"""Every numeric input of crazyflie_server, swept with a seeded mix of random floats, NaN, +-inf,
-0.0, denormals and huge finite doubles (1e39, 1e308).

Asserts (a) at the simulated firmware (what it decoded, from the world's ``state`` call) that no
value reached it that is not finite or outside what it accepts; (b) that every refusal is named:
on /rosout for topics (throttled per Crazyflie, topic, field and rule) and in the answer of a
service; (c) that the worker stayed alive (its status topic); (d) that the Crazyflie still flies
afterwards (a climb on the world's truth). Values a message field cannot carry (a float32 field
and 1e39) are refused by ROS's own serialisation in the caller and are not sent.
"""
from __future__ import annotations

import codecs
import math
import random
import sys
import time
import unittest
from typing import Any, Callable, Dict, List, Sequence, Tuple

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped, PoseStamped, Twist
from std_msgs.msg import Empty as EmptyMsg

from crazyflie_driver.crtp.ctypes import ctype
from crazyflie_driver.crtp.firmware_limits import MAX_ANGLE_DEG, MAX_RATE_DEG_S, MAX_THRUST
from crazyflie_driver.msg import FullState, Hover, Position, TrajectoryPolynomialPiece, VelocityWorld
from crazyflie_driver.sim.world_clock import WorldClock
from crazyflie_driver.srv import (
    AddCrazyflie,
    AddCrazyflieRequest,
    GoTo,
    GoToRequest,
    Land,
    LandRequest,
    RemoveCrazyflie,
    SetGroupMask,
    StartTrajectory,
    Stop,
    Takeoff,
    TakeoffRequest,
    UpdateParams,
    UploadTrajectory,
)
from support.rostest_support import (
    RosoutRecorder,
    TopicRecorder,
    add_crazyflies,
    registered_services,
    start_test_node,
    wait_connected,
    wait_until,
)

SEED = 16
URI = "radio://0/80/2M/E7E7E7E701"
PROBE_URI = "radio://0/80/2M/E7E7E7E702"
NS = "/crazyflie1"
NAN, INF = float("nan"), float("inf")
FLOAT32 = ctype("float")
#: Values every sweep starts with: non-finite, signed zero, denormals (double and float32), huge.
SPECIAL = (NAN, INF, -INF, -0.0, 5e-324, 1e-40, 1e39, -1e39, 1e308, -1e308, FLOAT32.high, -FLOAT32.high)
RANDOM_PER_FIELD = 6
#: Parameters whose values are swept (one of each C type the simulated firmware has writable), with their type.
#: The firmware declares no writable 16-bit signed parameter; the small table of the 2016.02 profile has one.
SWEPT_PARAMS = (("pid_rate/roll_kp", "float"), ("ring/solidRed", "uint8_t"), ("ring/fadeColor", "uint32_t"),
                ("sound/freq", "uint16_t"), ("radiotest/power", "int8_t"), ("colAv/vorIters", "int32_t"))
#: Swarm-wide services at the root (/takeoff, /land, /go_to, ...) are swept once the server offers them.
SWARM_SERVICES = ("/takeoff", "/land", "/go_to")


def fits_float32(v: float) -> bool:
    return math.isfinite(v) and FLOAT32.holds(v)


def fits_milli_int16(v: float) -> bool:
    return math.isfinite(v) and abs(int(v * 1000.0)) <= 32767


def values_for(rng: random.Random, float32_field: bool) -> List[float]:
    """SPECIAL and random floats (small, and of any magnitude a double has); a float32 message field
    cannot carry a finite value beyond the float32 range (ROS refuses to serialise it)."""
    out = list(SPECIAL)
    for _ in range(RANDOM_PER_FIELD):
        if rng.random() < 0.5:
            out.append(rng.uniform(-3.0, 3.0))
        else:
            out.append(rng.choice((-1.0, 1.0)) * 10.0 ** rng.uniform(-45.0, 45.0))
    if float32_field:
        out = [v for v in out if not math.isfinite(v) or fits_float32(v)]
    return out


def set_path(msg: Any, path: str, value: Any) -> None:
    *parents, leaf = path.split(".")
    for p in parents:
        msg = getattr(msg, p)
    setattr(msg, leaf, value)


def identity_pose(msg: PoseStamped) -> PoseStamped:
    msg.pose.orientation.w = 1.0
    return msg


def identity_full_state(msg: FullState) -> FullState:
    msg.pose.orientation.w = 1.0
    return msg


# (topic, message factory, [(field path, float32 field?, name the refusal uses, refused(value))])
F32, F64 = True, False
finite = math.isfinite
TOPICS: Sequence[Tuple[str, Callable[[], Any], Sequence[Tuple[str, bool, str, Callable[[float], bool]]]]] = (
    ("cmd_vel", Twist, [
        ("linear.x", F64, "cmd_vel linear.x is", lambda v: not finite(v)),
        ("linear.y", F64, "cmd_vel linear.y is", lambda v: not finite(v)),
        ("linear.z", F64, "cmd_vel linear.z is", lambda v: not finite(v)),
        ("angular.z", F64, "cmd_vel angular.z is", lambda v: not finite(v)),
        ("angular.x", F64, None, lambda v: False),      # not used by the mapping (as the original)
        ("angular.y", F64, None, lambda v: False)]),
    ("cmd_position", Position, [(f, F32, n, lambda v: not fits_float32(v))
                                for f, n in (("x", "x must"), ("y", "y must"), ("z", "z must"), ("yaw", "yaw must"))]),
    ("cmd_hover", Hover, [(f, F32, n, lambda v: not fits_float32(v))
                          for f, n in (("vx", "vx must"), ("vy", "vy must"), ("yawrate", "yaw rate must"),
                                       ("zDistance", "z must"))]),
    ("cmd_velocity_world", VelocityWorld, [(f, t, n, lambda v: not fits_float32(v))
                                           for f, t, n in (("vel.x", F64, "vx must"), ("vel.y", F64, "vy must"),
                                                           ("vel.z", F64, "vz must"),
                                                           ("yawRate", F32, "yaw rate must"))]),
    ("cmd_full_state", lambda: identity_full_state(FullState()),
     [("pose.position." + a, F64, "position " + a, lambda v: not fits_milli_int16(v)) for a in "xyz"]
     + [("twist.linear." + a, F64, "velocity " + a, lambda v: not fits_milli_int16(v)) for a in "xyz"]
     + [("acc." + a, F64, "acceleration " + a, lambda v: not fits_milli_int16(v)) for a in "xyz"]
     + [("twist.angular." + a, F64, "body rate " + a, lambda v: not fits_milli_int16(v)) for a in "xyz"]
     + [("pose.orientation." + a, F64, "quaternion", lambda v: not fits_float32(v)) for a in "xyzw"]),
    ("external_position", PointStamped, [("point." + a, F64, a + " must", lambda v: not fits_float32(v))
                                         for a in "xyz"]),
    ("external_pose", lambda: identity_pose(PoseStamped()),
     [("pose.position." + a, F64, a + " must", lambda v: not fits_float32(v)) for a in "xyz"]
     + [("pose.orientation." + a, F64, "q" + a + " must", lambda v: not fits_float32(v)) for a in "xyzw"]),
)


class InputSweep(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.world = start_test_node("input_sweep_test")
        cls.clock = WorldClock(cls.world.ping)
        cls.rosout = RosoutRecorder("/crazyflie_server")
        cls.status = TopicRecorder(NS + "/status", DiagnosticStatus)
        add_crazyflies([AddCrazyflieRequest(uri=URI, tf_prefix="crazyflie1", enable_logging=False,
                                            enable_parameters=True)])
        cls.rng = random.Random(SEED)
        cls.pubs = {topic: rospy.Publisher(NS + "/" + topic, factory().__class__, queue_size=100)
                    for topic, factory, _ in TOPICS}
        cls.stop_pub = rospy.Publisher(NS + "/cmd_stop", EmptyMsg, queue_size=10)
        assert wait_connected(list(cls.pubs.values()) + [cls.stop_pub], 10.0)
        cls.refused_calls: List[str] = []       # service answers to bad values
        cls.accepted_bad: List[str] = []        # a bad value a service said OK to (must stay empty)

    # -- helpers -------------------------------------------------------------------------------------------
    def firmware(self, uri: str = URI) -> Dict[str, Any]:
        return self.world.crazyflie_state(uri)

    def call(self, what: str, proxy, request, bad: bool, names: Sequence[str]) -> bool:
        """One service call; a refusal must name one of ``names``; a bad value must be refused."""
        try:
            proxy(request)
        except rospy.ServiceException as e:
            text = str(e)       # rospy quotes the answer as bytes: its backslashes come doubled
            texts = (text, codecs.decode(text.encode("latin-1", "backslashreplace"), "unicode_escape"))
            self.assertTrue(any(n in t for n in names for t in texts),
                            "%s: refusal does not name %s: %s" % (what, names, text))
            self.refused_calls.append(what)
            return False
        if bad:
            self.accepted_bad.append(what)
        return True

    def high_level_stop(self, ns: str = NS) -> None:
        rospy.ServiceProxy(ns + "/stop", Stop)(groupMask=0)

    # -- topics --------------------------------------------------------------------------------------------
    def test_a_topics(self):
        for topic, factory, fields in TOPICS:
            pub = self.pubs[topic]
            for path, f32, name, refused in fields:
                t0 = time.monotonic()
                sent_refused = False
                for v in values_for(self.rng, f32):
                    msg = factory()
                    set_path(msg, path, v)
                    pub.publish(msg)
                    sent_refused = sent_refused or refused(v)
                    time.sleep(0.002)
                if name is None:
                    continue
                msg = factory()
                set_path(msg, path, NAN)        # the last one is refused for sure (queues keep the newest)
                pub.publish(msg)
                self.assertTrue(sent_refused)
                want = "%s refused: " % topic if topic != "cmd_vel" else "cmd_vel refused: "
                named = wait_until(lambda: [m for m in self.rosout.find(want + name) if m], 5.0)
                self.assertTrue(named, "%s.%s: no refusal naming it on /rosout (%s...) since %.1f s" % (
                    topic, path, want + name, time.monotonic() - t0))
            # end of the topic: motors off (the random finite values were flown for a few ms each)
            if topic == "cmd_vel":
                pub.publish(Twist())
            else:
                self.stop_pub.publish(EmptyMsg())
        self.check_firmware(expect=("set_rpyt.3", "set_setpoint.0.position.0", "set_setpoint.0.velocity.0",
                                    "set_setpoint.0.quaternion.3", "external_measurement.0.0",
                                    "external_measurement.1.3"))

    # -- services ------------------------------------------------------------------------------------------
    def test_b_high_level_services(self):
        self.sweep_high_level(NS)
        self.check_firmware(expect=("high_level.takeoff.height", "high_level.land.duration", "high_level.go_to.goal.2",
                                    "high_level.go_to.yaw"))

    def sweep_high_level(self, ns: str, services: Sequence[str] = ("/takeoff", "/land", "/go_to")) -> None:
        """takeoff, land (height, duration, group mask) and go_to (goal, yaw, duration) under ``ns``."""
        rng = self.rng
        durations = (0.0, -0.5, 1e-9, 2.0, 1e6, -2e9)
        stop = lambda: rospy.ServiceProxy(ns + "/stop", Stop)(groupMask=0)
        for service, kind, cls in (("/takeoff", Takeoff, TakeoffRequest), ("/land", Land, LandRequest)):
            if service not in services:
                continue
            proxy, what = rospy.ServiceProxy(ns + service, kind), ns + service
            for v in values_for(rng, True):
                self.call("%s height %r" % (what, v), proxy, cls(groupMask=0, height=v, duration=rospy.Duration(2.0)),
                          not fits_float32(v), ["height"])
                stop()
            for d in durations:
                # a land of no time stops the motors in the air, and a group mask that addresses no
                # Crazyflie (each one here is in group mask 0) does nothing: both refused by name
                mask = rng.choice((0, 1, 255))
                self.call("%s duration %r group mask %d" % (what, d, mask), proxy,
                          cls(groupMask=mask, height=0.3 if service == "/takeoff" else 0.0,
                              duration=rospy.Duration.from_sec(d)),
                          d < 0 or (service == "/land" and d == 0) or mask != 0, ["duration", "group mask"])
                stop()
        if "/go_to" not in services:
            return
        go_to = rospy.ServiceProxy(ns + "/go_to", GoTo)
        for field, name in (("goal.x", "goal x"), ("goal.y", "goal y"), ("goal.z", "goal z"), ("yaw", "yaw")):
            for v in values_for(rng, field == "yaw"):
                req = GoToRequest(groupMask=0, relative=rng.random() < 0.5, duration=rospy.Duration(1.0))
                set_path(req, field, v)
                self.call("%s/go_to %s %r" % (ns, field, v), go_to, req, not fits_float32(v), [name])
                stop()
        for d in durations:
            self.call("%s/go_to duration %r" % (ns, d), go_to,
                      GoToRequest(groupMask=0, duration=rospy.Duration.from_sec(d)), d < 0, ["duration"])
            stop()

    def test_c_trajectories_and_group_mask(self):
        upload = rospy.ServiceProxy(NS + "/upload_trajectory", UploadTrajectory)
        start = rospy.ServiceProxy(NS + "/start_trajectory", StartTrajectory)
        rng = self.rng

        def piece(duration=1.0):
            p = TrajectoryPolynomialPiece(duration=rospy.Duration.from_sec(duration))
            p.poly_x, p.poly_y, p.poly_z, p.poly_yaw = ([0.0] * 8 for _ in range(4))
            return p
        for axis in ("poly_x", "poly_y", "poly_z", "poly_yaw"):
            for k in range(8):
                for v in (NAN, INF, -INF, -0.0, 1e-40, rng.choice((-1.0, 1.0)) * 10.0 ** rng.uniform(-45, 38)):
                    p = piece()
                    getattr(p, axis)[k] = v
                    self.call("upload %s[%d] %r" % (axis, k, v), upload,
                              UploadTrajectory._request_class(trajectoryId=2, pieceOffset=0, pieces=[p]),
                              not fits_float32(v), ["%s coefficient %d" % (axis.split("_")[1], k)])
        for d in (0.0, -1.0, 1e-9, 1e6):
            self.call("upload duration %r" % d, upload,
                      UploadTrajectory._request_class(trajectoryId=2, pieceOffset=0, pieces=[piece(d)]),
                      not d > 0, ["duration"])
        # a harmless trajectory (stays on the floor) to start with swept time scales
        self.assertTrue(self.call("upload safe", upload,
                                  UploadTrajectory._request_class(trajectoryId=1, pieceOffset=0, pieces=[piece(1.0)]),
                                  False, []))
        for v in values_for(rng, True) + [0.0, -1.0]:
            self.call("start_trajectory timescale %r" % v, start,
                      StartTrajectory._request_class(groupMask=0, trajectoryId=1, timescale=v, reversed=False,
                                                     relative=False), not (fits_float32(v) and v > 0), ["timescale"])
            self.high_level_stop()
        group_mask = rospy.ServiceProxy(NS + "/set_group_mask", SetGroupMask)
        for mask in (0, 1, 128, 255, rng.randrange(256)):
            self.assertTrue(self.call("set_group_mask %d" % mask, group_mask,
                                      SetGroupMask._request_class(groupMask=mask), False, []))
        group_mask(groupMask=0)
        self.check_firmware(expect=("high_level.start_trajectory.timescale", "high_level.set_group_mask.mask",
                                    "trajectory 1.", "trajectory 2."))

    def test_d_update_params(self):
        update = rospy.ServiceProxy(NS + "/update_params", UpdateParams)
        original = {p: rospy.get_param(NS + "/" + p) for p, _ in SWEPT_PARAMS}
        try:
            for p, type_name in SWEPT_PARAMS:
                ct = ctype(type_name)
                values = values_for(self.rng, False) + [3.0, 3.5, float(ct.low) - 1, float(ct.high) + 1,
                                                         float(ct.low), float(ct.high)]
                for v in values:
                    rospy.set_param(NS + "/" + p, v)
                    bad = not math.isfinite(v) or not ct.holds(v) or (not ct.is_float and v != int(v))
                    self.call("update_params %s = %r" % (p, v), update, UpdateParams._request_class(params=[p]),
                              bad, [p.replace("/", ".")])
        finally:
            for p, v in original.items():
                rospy.set_param(NS + "/" + p, v)
            update(params=[p for p, _ in SWEPT_PARAMS])
        fw_params = self.firmware()["params"]
        for p, v in original.items():
            self.assertEqual(fw_params[p.replace("/", ".")], v)
        # names the ROS parameter server cannot carry: refused by name, the server keeps serving
        for name in ("pid_rate/roll\x00kp", "pid_rate/roll\x01kp", "pid_rate/", "nogroup"):
            self.call("update_params name %r" % name, update, UpdateParams._request_class(params=[name]), True,
                      [repr(name)])
        self.check_firmware(expect=["param." + p.replace("/", ".") for p, _ in SWEPT_PARAMS])

    def test_e_add_crazyflie_trims(self):
        remove = rospy.ServiceProxy("/remove_crazyflie", RemoveCrazyflie)
        add = rospy.ServiceProxy("/add_crazyflie", AddCrazyflie)
        accepted = 0
        for field in ("roll_trim", "pitch_trim"):
            # every add that is accepted costs a connect: the special values and two random ones
            for v in (NAN, INF, -INF, FLOAT32.high, -0.0, 1e-40, 91.0, self.rng.uniform(-3.0, 3.0),
                      self.rng.choice((-1.0, 1.0)) * 10.0 ** self.rng.uniform(-45.0, 38.0)):
                req = AddCrazyflieRequest(uri=PROBE_URI, tf_prefix="trim_probe", enable_logging=False,
                                          enable_parameters=False)
                setattr(req, field, v)
                bad = not math.isfinite(v) or abs(v) > MAX_ANGLE_DEG
                if self.call("add %s %r" % (field, v), add, req, bad, [field]):
                    accepted += 1
                    pub = rospy.Publisher("/trim_probe/cmd_vel", Twist, queue_size=1)
                    wait_until(lambda: pub.get_num_connections() > 0, 5.0)
                    before = self.firmware(PROBE_URI)["setpoints"]
                    pub.publish(Twist())        # a zero cmd_vel: the trim alone goes on the wire
                    wait_until(lambda: self.firmware(PROBE_URI)["setpoints"] > before, 5.0)
                    pub.unregister()
                    remove(uri=PROBE_URI)
        self.assertGreater(accepted, 0)
        self.check_firmware(PROBE_URI, expect=("set_rpyt.0", "set_rpyt.1"))

    def test_f_swarm_services_when_served(self):
        """The swarm-wide services at the root (/takeoff, /land, /go_to ...), swept like the per-Crazyflie
        ones when the server offers them (a server started with a swarm file); skipped otherwise."""
        served = [s for s in SWARM_SERVICES if s in registered_services()]
        print("swarm-wide services served: %s" % (served or "none"))
        if not served:
            self.skipTest("no swarm-wide services in this server")
        self.sweep_high_level("", served)
        self.check_firmware()

    # -- the checks after every sweep -------------------------------------------------------------------------
    def check_firmware(self, uri: str = URI, expect: Sequence[str] = ()) -> None:
        """(a) nothing non-finite or out of range reached the firmware; (c) the worker is alive.
        ``expect``: fields the sweep must have reached the firmware through (so the check is not empty)."""
        fw = self.firmware(uri)
        self.assertFalse(fw["halted"], fw["halted"])
        decoded = dict(fw["decoded"])
        decoded.update(fw["trajectories"])
        missing = [k for k in expect if not any(name.startswith(k) for name in decoded)]
        self.assertEqual(missing, [], "the sweep did not reach these fields of the firmware")
        print("%s: %d fields decoded, %d values" % (uri, len(decoded), sum(v["count"] for v in decoded.values())))
        bad = {k: v for k, v in decoded.items() if v["non_finite"]}
        self.assertEqual(bad, {}, "non-finite values reached the firmware")
        limits = {"set_rpyt.0": MAX_ANGLE_DEG, "set_rpyt.1": MAX_ANGLE_DEG, "set_rpyt.2": MAX_RATE_DEG_S,
                  "set_rpyt.3": MAX_THRUST}       # roll, pitch (angle mode), yaw rate, thrust
        for key, limit in limits.items():
            if key in decoded:
                self.assertLessEqual(max(abs(decoded[key]["min"]), abs(decoded[key]["max"])), limit, key)
        if "set_rpyt.3" in decoded:
            self.assertGreaterEqual(decoded["set_rpyt.3"]["min"], 0)
        for p, type_name in SWEPT_PARAMS:
            entry = decoded.get("param." + p.replace("/", "."))
            if entry:
                ct = ctype(type_name)
                self.assertTrue(ct.holds(entry["min"]) and ct.holds(entry["max"]), (p, entry))
        for key, entry in decoded.items():     # durations and time scales the planner divides by
            if key.endswith(".duration"):
                self.assertGreaterEqual(entry["min"], 0.0, (key, entry))
            if key.endswith(".timescale"):
                self.assertGreater(entry["min"], 0.0, (key, entry))
        self.assertEqual(self.accepted_bad, [], "bad values a service accepted")
        if uri == URI:
            self.assertTrue(wait_until(lambda: self.status.latest() is not None, 5.0))
            st = self.status.latest()
            values = {kv.key: kv.value for kv in st.values}
            self.assertEqual((values["state"], values["restarts"]), ("running", "0"), (st.message, values))
            self.assertNotEqual(st.level, DiagnosticStatus.ERROR, st.message)

    def test_z_still_flies(self):
        """(d) after everything: a climb under thrust, seen on the world's truth."""
        self.high_level_stop()
        pub = self.pubs["cmd_vel"]
        truth = lambda: self.world.control("vehicle_state", uri=URI)
        self.assertTrue(self.clock.wait_until(lambda: truth()["on_ground"], 10.0)[0], truth())
        z0 = truth()["position"][2]
        climb = Twist()
        climb.linear.z = 52000.0

        def climbing():
            pub.publish(climb)
            return truth()["position"][2] > z0 + 0.2
        risen, _ = self.clock.wait_until(climbing, 3.0)
        pub.publish(Twist())
        self.assertTrue(risen, truth())
        print("sweep: %d service calls refused by name; climbed from z %.2f to %.2f m" % (
            len(self.refused_calls), z0, truth()["position"][2]))
        self.check_firmware()


if __name__ == "__main__":
    rostest.rosrun("crazyflie_driver", "input_sweep", InputSweep, sys.argv)
