"""RTL's destination and altitude by PX4's RTL_TYPE, with rally points and their altitudes (pure)."""

import pytest

from autopilot.commander.rtl import Destination, return_altitude, return_destination
from autopilot.mission.plans import RallyPoint
from autopilot.params.definitions import RTL_TYPES_REFUSED, default_parameters

HOME = (0.0, 0.0, 0.0)
NEAR = RallyPoint(10.0, 0.0, 12.0, True)  # 12 m above home
FAR = RallyPoint(-40.0, 0.0, 480.0 - 488.0, False)  # AMSL 480 m with the origin at 488 m: 8 m below


@pytest.mark.parametrize(
    "rtl_type, position, rally, expected",
    [
        (0, (9.0, 0.0, 3.0), [NEAR, FAR], "rally point 0"),  # the closest of home and rally points
        (0, (2.0, 0.0, 3.0), [NEAR, FAR], "launch"),
        (3, (2.0, 0.0, 3.0), [NEAR, FAR], "launch"),  # (no mission landing here: as 0)
        (1, (2.0, 0.0, 3.0), [NEAR, FAR], "rally point 0"),  # a rally point even if home is closer
        (1, (-30.0, 0.0, 3.0), [NEAR, FAR], "rally point 1"),
        (1, (2.0, 0.0, 3.0), [], "launch"),  # none: home
        (5, (2.0, 0.0, 3.0), [NEAR], "rally point 0"),
        (5, (2.0, 5.0, 3.0), [], "here"),  # none: land where it is
    ],
)
def test_the_destination_by_rtl_type(rtl_type, position, rally, expected):
    assert return_destination(rtl_type, position, HOME, rally).name == expected


def test_the_return_altitude_counts_from_the_destination():
    home = (0.0, 0.0, 1.0)  # a home above the local origin (armed on a roof)
    to_near = return_destination(1, (2.0, 0.0, 3.0), home, [NEAR])
    assert to_near.position_m == (10.0, 0.0, 13.0)  # relative: above the current home
    assert return_altitude(3.0, to_near, 5.0) == 18.0  # 5 m above the rally point
    assert return_altitude(30.0, to_near, 5.0) == 30.0  # never lower than where it is
    to_far = return_destination(1, (-30.0, 0.0, 3.0), home, [NEAR, FAR])
    assert to_far.position_m[2] == -8.0  # absolute: below the origin
    assert return_altitude(3.0, to_far, 5.0) == 3.0  # PX4: max(current, -8 + 5)
    assert return_altitude(3.0, Destination(home, "launch"), 5.0) == 6.0


def test_rtl_types_without_their_prerequisites_are_refused():
    params = default_parameters()
    for value, why in RTL_TYPES_REFUSED.items():
        assert why in params.set("RTL_TYPE", value)
    for value in (0, 1, 3, 5):
        assert params.set("RTL_TYPE", value) is None
