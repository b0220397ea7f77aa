"""The launcher turns the lockstep busy-wait off when its vehicles' processes outnumber the cores."""

from quadcommon.config import SPIN_ENV
from sitl.launcher import spin_environment


def test_spin_off_only_when_the_processes_outnumber_the_cores_and_the_user_did_not_choose():
    assert spin_environment(1, {"PATH": "/bin"}, cores=2) is None  # one pair, two cores: spin pays
    env = spin_environment(2, {"PATH": "/bin"}, cores=2)
    assert env == {"PATH": "/bin", SPIN_ENV: "0"}
    assert spin_environment(4, {"PATH": "/bin"}, cores=8) is None
    assert spin_environment(5, {"PATH": "/bin"}, cores=8)[SPIN_ENV] == "0"
    assert spin_environment(3, {SPIN_ENV: "0.001"}, cores=2) is None  # the user's choice stands
