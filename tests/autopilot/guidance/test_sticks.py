"""The sticks' shapes and stream (pure, simulation time): PX4's tilt, throttle curve, ACRO expo,
deadzone; the stream's loss and return, and what counts as a stick moving (the override)."""

import math

import pytest

from autopilot.guidance.sticks import (
    LOST,
    REGAINED,
    Sticks,
    StickStream,
    acro_rate,
    beyond_deadzone,
    stick_tilt,
    throttle_curve,
)
from quadcommon.rigid_body import rotation_matrix

TILT = math.radians(35.0)


def tilt_of(phi: float, theta: float) -> float:
    """The angle between the body's up axis and the vertical."""
    return math.acos(rotation_matrix(phi, theta, 0.0)[2][2])


def test_stick_tilt_directions_and_the_limit():
    assert stick_tilt(0.0, 0.0, TILT) == (0.0, 0.0)
    phi, theta = stick_tilt(1.0, 0.0, TILT)  # full forward: nose down (+theta in the paper's frame)
    assert phi == pytest.approx(0.0, abs=1e-12) and theta == pytest.approx(TILT)
    phi, theta = stick_tilt(0.0, 1.0, TILT)  # full left: roll left (-phi)
    assert phi == pytest.approx(-TILT) and theta == pytest.approx(0.0, abs=1e-12)
    phi, theta = stick_tilt(0.5, 0.0, TILT)  # proportional
    assert theta == pytest.approx(0.5 * TILT)
    # Both full: the tilt is the limit, not sqrt(2) times it, pointing forward-left.
    phi, theta = stick_tilt(1.0, 1.0, TILT)
    assert tilt_of(phi, theta) == pytest.approx(TILT)
    assert phi < 0.0 < theta  # (ZYX angles of a diagonal tilt are not equal: roll is taken last)
    assert tilt_of(*stick_tilt(0.3, -0.4, TILT)) == pytest.approx(0.5 * TILT)


def test_throttle_curve_rescaled_to_the_hover_thrust_and_linear():
    hover, lo, hi = 0.259, 0.08, 1.0
    assert throttle_curve(0.0, hover, lo, hi, True) == pytest.approx(hover)
    assert throttle_curve(-1.0, hover, lo, hi, True) == pytest.approx(lo)
    assert throttle_curve(1.0, hover, lo, hi, True) == pytest.approx(hi)
    assert throttle_curve(0.5, hover, lo, hi, True) == pytest.approx(hover + 0.5 * (hi - hover))
    assert throttle_curve(2.0, hover, lo, hi, True) == pytest.approx(hi)  # clipped
    assert throttle_curve(0.0, hover, lo, hi, False) == pytest.approx(0.5 * (lo + hi))
    values = [throttle_curve(u / 10.0, hover, lo, hi, True) for u in range(-10, 11)]
    assert values == sorted(values)


def test_acro_rate_expo_and_super_expo():
    r = math.radians(100.0)
    assert acro_rate(0.5, r, 0.0, 0.0) == pytest.approx(0.5 * r)  # linear by default (PX4)
    assert acro_rate(-1.0, r, 0.0, 0.0) == pytest.approx(-r)
    assert acro_rate(0.5, r, 1.0, 0.0) == pytest.approx(0.125 * r)  # cubic
    for expo, super_expo in ((0.69, 0.7), (0.3, 0.95)):
        assert acro_rate(1.0, r, expo, super_expo) == pytest.approx(r)  # full stick: full rate
        assert 0.0 < acro_rate(0.5, r, expo, super_expo) < 0.5 * r  # softer near the centre


def test_deadzone_rescaled_from_its_edge():
    assert beyond_deadzone(0.09, 0.1) == 0.0
    assert beyond_deadzone(-0.55, 0.1) == pytest.approx(-0.5)
    assert beyond_deadzone(1.0, 0.1) == pytest.approx(1.0)


def test_the_stream_is_lost_after_the_timeout_and_regained_with_the_gap():
    stream = StickStream()
    assert stream.poll(0.0, 0.5) is None  # nothing ever came: nothing to lose
    for k in range(5):
        stream.receive(Sticks(0.1 * k), 0.5, 0.3)
        assert stream.poll(0.1 * k, 0.5) is None
    assert stream.fresh(0.9, 0.5) is not None
    assert stream.poll(0.9, 0.5) is None  # 0.5 s after the last: still fresh
    assert stream.poll(0.91, 0.5) == (LOST, 0.0)
    assert stream.fresh(0.91, 0.5) is None
    assert stream.poll(2.0, 0.5) is None  # announced once
    stream.receive(Sticks(2.7), 0.5, 0.3)
    kind, gap = stream.poll(2.7, 0.5)
    assert kind == REGAINED and gap == pytest.approx(2.3)
    # The simulator restarted (time went back): sticks stamped in the old run are not fresh.
    assert stream.fresh(0.1, 0.5) is None and stream.poll(0.1, 0.5) == (LOST, 0.0)


def _feed(stream: StickStream, values, start=0.0, every=0.1, threshold=0.3) -> bool:
    """Sticks with these forward deflections at 10 Hz; whether an override was requested."""
    for k, forward in enumerate(values):
        stream.receive(Sticks(start + every * k, forward=forward), 0.5, threshold)
    return stream.take_override()


def test_a_stick_moving_requests_the_override_a_stick_held_does_not():
    assert not _feed(StickStream(), [1.0] * 20)  # held at full deflection from the first sample
    assert not _feed(StickStream(), [0.0] * 10 + [0.02 * k for k in range(10)])  # 0.2 travel/s < 0.3
    assert _feed(StickStream(), [0.0] * 10 + [0.5] * 10)  # a step: moving
    stream = StickStream()
    assert _feed(stream, [0.0] * 5 + [0.5] * 5)
    assert not stream.take_override()  # consumed
    # After a loss the first sample starts afresh: coming back deflected is no movement.
    assert not _feed(stream, [1.0] * 5, start=10.0)
    # A flood at one instant carries no speed, whatever it holds.
    stream = StickStream()
    _feed(stream, [0.0] * 3)
    for k in range(1000):
        stream.receive(Sticks(0.2, forward=(-1.0) ** k), 0.5, 0.3)
    assert not stream.take_override()
