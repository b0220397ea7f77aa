"""Wall-clock pacing of the simulator process (the one place its loop reads a clock)."""

import time

import pytest

from simulator.pacing import Pacer

pytestmark = pytest.mark.timeout(30)


def test_speed_factor_sets_the_earliest_wall_time_of_each_frame():
    """At 2x, 0.2 s of simulated time cannot take less than 0.1 s of wall time (a loaded machine
    may make it slower, never faster: only the lower bound is asserted)."""
    pacer = Pacer(2.0, log=lambda text: None, running=lambda: True)
    start = time.perf_counter()
    for k in range(1, 101):
        pacer.pace(k * 0.002)
    assert time.perf_counter() - start >= 0.1 - 1e-3


def test_max_speed_never_sleeps_but_an_idle_simulator_goes_at_real_time():
    pacer = Pacer(None, log=lambda text: None, running=lambda: True)
    start = time.perf_counter()
    for k in range(1, 1001):
        pacer.pace(k * 0.002)  # "max": 2 s of simulated time, no sleeping at all
    busy = time.perf_counter() - start
    assert busy < 1.0  # far below the 2 s it would take paced (a bound that cannot flake low)
    start = time.perf_counter()
    for k in range(1, 51):
        pacer.pace(10.0 + k * 0.002, idle=True)
    assert time.perf_counter() - start >= 0.1 - 1e-3 - 0.002  # 0.1 s at 1x (first frame anchors)


def test_far_behind_re_anchors_instead_of_sprinting():
    pacer = Pacer(1.0, log=lambda text: None, running=lambda: True)
    pacer.pace(0.0)
    time.sleep(0.25)  # a stall longer than RESYNC_BEHIND_S
    pacer.pace(0.002)
    assert pacer.overruns == 1
    start = time.perf_counter()
    pacer.pace(0.052)  # the schedule moved: the next frame waits its 50 ms again
    assert time.perf_counter() - start >= 0.045


def test_a_stop_request_ends_a_long_sleep():
    stop = {"now": False}
    pacer = Pacer(0.001, log=lambda text: None, running=lambda: not stop["now"])
    pacer.pace(0.0)
    stop["now"] = True
    start = time.perf_counter()
    pacer.pace(10.0)  # 10 000 s of wall time at 0.001x, unless the stop is seen
    assert time.perf_counter() - start < 1.0
