"""The joystick reader: js_event parsing, joy's scaling and sign, publication timing, missing and
unplugged devices. The device is a FIFO (or a file) carrying js_event records written here."""
from __future__ import annotations

import errno
import logging
import struct
import time

import pytest

from crazyflie_demo.fake_joystick import FakeJoystick
from crazyflie_demo.joystick import (
    EVENT_SIZE,
    JS_EVENT_AXIS,
    JS_EVENT_BUTTON,
    JS_EVENT_INIT,
    Joystick,
    JoystickModel,
    JsEvent,
    clamp_deadzone,
    open_failure_message,
    pack_event,
    parse_events,
    scale_axis,
)


def poll_until(js: Joystick, predicate, timeout: float = 2.0):
    """Published states until one satisfies predicate (returned last)."""
    seen = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        state = js.poll(0.02)
        if state is not None:
            seen.append(state)
            if predicate(state):
                return seen
    raise AssertionError("no matching state within %.1f s; published: %r" % (timeout, seen))


def drain(js: Joystick, duration: float):
    out = []
    deadline = time.monotonic() + duration
    while time.monotonic() < deadline:
        state = js.poll(0.01)
        if state is not None:
            out.append((time.monotonic(), state))
    return out


@pytest.fixture
def pad(tmp_path):
    fake = FakeJoystick(str(tmp_path / "js0"), axes=6, buttons=4)
    yield fake
    fake.close()


def open_pair(pad: FakeJoystick, **options) -> Joystick:
    js = Joystick(pad.path, **options)
    assert js.poll(0.0) is None and js.is_open      # opened; nothing to say yet
    pad.plug_in()
    return js


# --- wire format -----------------------------------------------------------------------------

def test_event_layout_is_the_kernels_struct_js_event():
    data = pack_event(0x01020304, -2, JS_EVENT_AXIS | JS_EVENT_INIT, 7)
    assert len(data) == EVENT_SIZE == 8
    assert struct.unpack("=IhBB", data) == (0x01020304, -2, 0x82, 7)
    (ev,), rest = parse_events(data + data[:3])
    assert ev == JsEvent(0x01020304, -2, 0x82, 7) and ev.is_init and ev.kind == JS_EVENT_AXIS
    assert rest == data[:3]                         # a partial record waits for its remainder


# --- scaling ---------------------------------------------------------------------------------

def test_stick_up_or_left_is_positive_and_full_travel_reaches_one():
    assert scale_axis(-32767, 0.05) == pytest.approx(1.0)
    assert scale_axis(32767, 0.05) == pytest.approx(-1.0)
    assert scale_axis(-32768, 0.05) == 1.0          # the extra negative count is clamped
    assert scale_axis(-16384, 0.0) == pytest.approx(16384 / 32767)


def test_deadzone_zeroes_the_centre_and_rescales_outside():
    dz = 0.1
    assert scale_axis(int(-0.099 * 32767), dz) == 0.0
    assert scale_axis(int(0.099 * 32767), dz) == 0.0
    halfway = -(dz + 0.5 * (1 - dz)) * 32767        # half of the travel beyond the deadzone
    assert scale_axis(int(round(halfway)), dz) == pytest.approx(0.5, abs=1e-4)
    just_out = scale_axis(int(-0.11 * 32767), dz)
    assert 0.0 < just_out < 0.02                     # continuous at the deadzone's edge


def test_deadzone_is_bounded_like_joy():
    assert clamp_deadzone(-0.2) == pytest.approx(0.2)
    assert clamp_deadzone(1.5) == pytest.approx(0.9)
    assert JoystickModel(0.05).deadzone == pytest.approx(0.05)


def test_initial_axis_values_are_not_trusted_but_initial_buttons_are():
    model = JoystickModel()
    model.apply(JsEvent(0, -20000, JS_EVENT_AXIS | JS_EVENT_INIT, 2))
    model.apply(JsEvent(0, 1, JS_EVENT_BUTTON | JS_EVENT_INIT, 1))
    assert model.state.axes == [0.0, 0.0, 0.0] and model.state.buttons == [0, 1]
    model.apply(JsEvent(5, -20000, JS_EVENT_AXIS, 2))
    assert model.state.axes[2] == pytest.approx(scale_axis(-20000, 0.05)) and model.state.axes[2] > 0


# --- publication over a FIFO -----------------------------------------------------------------

def test_initial_state_is_published_once_the_init_events_are_in(pad):
    pad.axes[1] = -30000                             # held up while plugged in: reads 0 until moved
    pad.buttons[3] = 1
    js = open_pair(pad)
    (first,) = poll_until(js, lambda s: True)
    assert first.axes == [0.0] * 6 and first.buttons == [0, 0, 0, 1]
    assert js.events == 10


def test_axis_moves_are_coalesced_and_sign_follows_joy(pad):
    js = open_pair(pad, coalesce_interval=0.05)
    poll_until(js, lambda s: True)
    t0 = time.monotonic()
    pad.move_axes([(0, -32767), (1, 32767)])          # left and down in one burst
    assert drain(js, 0.02) == []                      # still coalescing
    pad.move_axis(4, -16384)                          # within the coalesce interval
    states = drain(js, 0.3)
    assert len(states) == 1, states                   # one message for the three moves
    assert 0.045 <= states[0][0] - t0 < 0.12          # sent one interval after the first move
    axes = states[0][1].axes
    assert axes[0] == pytest.approx(1.0) and axes[1] == pytest.approx(-1.0)
    assert axes[4] == pytest.approx(scale_axis(-16384, 0.05)) and axes[4] > 0.45


def test_button_change_is_published_without_waiting_for_the_coalesce_interval(pad):
    js = open_pair(pad, coalesce_interval=0.5)
    poll_until(js, lambda s: True, timeout=2.0)
    t0 = time.monotonic()
    pad.set_button(2, True)
    seen = poll_until(js, lambda s: s.buttons[2] == 1, timeout=1.0)
    assert time.monotonic() - t0 < 0.2 and len(seen) == 1
    pad.set_button(2, False)
    assert poll_until(js, lambda s: True)[-1].buttons == [0, 0, 0, 0]


class StepClock:
    """The joystick's clock, advanced by the test in whole milliseconds (the host's load cannot stretch it)."""

    def __init__(self):
        self.ms = 0

    def __call__(self) -> float:
        return self.ms / 1000.0


def test_autorepeat_resends_the_last_state_at_its_rate(pad):
    clock = StepClock()
    step_ms = 10
    js = open_pair(pad, autorepeat_rate=20.0, clock=clock)

    def poll_step():
        clock.ms += step_ms
        return js.poll(0.0)

    assert any(poll_step() is not None for _ in range(100))            # the initial state
    pad.move_axis(3, 20000)
    assert any((s is not None and s.axes[3] < 0) for s in (poll_step() for _ in range(100)))
    states = []
    for _ in range(50):                                                  # 0.5 s on the joystick's clock
        state = poll_step()
        if state is not None:
            states.append((clock(), state))
    assert len(states) == 10, [t for t, _ in states]                    # 20 Hz over 0.5 s
    assert all(s.axes[3] == pytest.approx(scale_axis(20000, 0.05)) for _, s in states)
    gaps = [b[0] - a[0] for a, b in zip(states, states[1:])]
    assert all(g == pytest.approx(0.05) for g in gaps), gaps


def test_without_autorepeat_nothing_is_sent_while_nothing_changes(pad):
    js = open_pair(pad)
    poll_until(js, lambda s: True)
    assert drain(js, 0.3) == []


def test_unplug_publishes_a_neutral_state_then_the_device_is_reopened(pad, caplog):
    js = open_pair(pad)
    poll_until(js, lambda s: True)
    pad.move_axis(1, -32767)                           # thrust stick fully up
    pad.set_button(0, True)
    poll_until(js, lambda s: s.axes[1] == pytest.approx(1.0) and s.buttons[0] == 1)
    with caplog.at_level(logging.WARNING, logger="crazyflie_demo.joystick"):
        pad.unplug()
        (neutral,) = poll_until(js, lambda s: True)
    assert neutral.axes == [0.0] * 6 and neutral.buttons == [0] * 4
    assert "lost" in caplog.text and pad.path in caplog.text
    pad.axes[1] = 0
    pad.buttons[0] = 0
    deadline = time.monotonic() + 2.0
    while not js.is_open and time.monotonic() < deadline:
        js.poll(0.02)
    assert js.is_open and js.opens == 2
    pad.plug_in()
    poll_until(js, lambda s: True)
    pad.move_axis(5, 32767)
    assert poll_until(js, lambda s: s.axes[5] == pytest.approx(-1.0))


def test_missing_device_is_retried_with_a_message_naming_it(tmp_path, caplog):
    path = str(tmp_path / "js7")
    js = Joystick(path, retry_interval=0.05)
    with caplog.at_level(logging.ERROR, logger="crazyflie_demo.joystick"):
        t0 = time.monotonic()
        for _ in range(5):
            assert js.poll(0.02) is None
        assert time.monotonic() - t0 < 1.0            # bounded waits, no hang
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == 1, errors                     # said once, not on every retry
    assert path in errors[0] and "no such device" in errors[0]
    pad = FakeJoystick(path, axes=2, buttons=1)
    try:
        deadline = time.monotonic() + 2.0
        while not js.is_open and time.monotonic() < deadline:
            js.poll(0.02)
        assert js.is_open
        pad.plug_in()
        pad.move_axis(0, -32767)
        assert poll_until(js, lambda s: s.axes == [pytest.approx(1.0), 0.0])
    finally:
        pad.close()


def test_permission_problem_names_the_input_group():
    msg = open_failure_message("/dev/input/js0", OSError(errno.EACCES, "Permission denied"))
    assert "/dev/input/js0" in msg and "input" in msg and "group" in msg
    msg = open_failure_message("/dev/input/js1", OSError(errno.ENOENT, "No such file"))
    assert "/dev/input/js1" in msg and "plugged in" in msg


def test_a_recorded_file_replays_then_counts_as_unplugged(tmp_path):
    path = tmp_path / "recording"
    data = pack_event(0, 0, JS_EVENT_AXIS | JS_EVENT_INIT, 0) + pack_event(0, 0, JS_EVENT_BUTTON | JS_EVENT_INIT, 0)
    data += pack_event(10, 32767, JS_EVENT_AXIS, 0) + pack_event(20, 1, JS_EVENT_BUTTON, 0)
    path.write_bytes(data)
    js = Joystick(str(path), coalesce_interval=0.0)
    states = poll_until(js, lambda s: s.axes == [0.0] and s.buttons == [0])   # the final neutral
    assert any(s.axes == [pytest.approx(-1.0)] and s.buttons == [1] for s in states), states


def test_bad_rates_are_refused_with_the_parameter_name(tmp_path):
    with pytest.raises(ValueError, match="autorepeat_rate"):
        Joystick(str(tmp_path / "x"), autorepeat_rate=-1)
    with pytest.raises(ValueError, match="coalesce_interval"):
        Joystick(str(tmp_path / "x"), coalesce_interval=-0.1)
