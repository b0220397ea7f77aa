"""The flying scripts wait until the vehicle is ready to arm, as PX4 clients do (SYS_STATUS's
pre-arm bit, the landed state), instead of arming into a refusal; in simulation time on the
in-process stack, with gcs_scripts/link.py's client unchanged on it."""

from __future__ import annotations

import pytest

from gcs_scripts import fly_setpoints
from gcs_scripts.link import LinkTimeout

from ..stack import connect, make_stack

pytestmark = pytest.mark.timeout(240)


def test_fly_setpoints_waits_for_the_ekf_then_arms_and_flies(capsys) -> None:
    """Right after start-up on GPS + EKF (``quadsitl up --estimator ekf --sensors gps``): the
    filter aligns, then converges; the script says so, arms once the vehicle is armable (no
    refusal) and flies."""
    stack = make_stack(sensors="gps", estimator="ekf")
    link = connect(stack)
    assert link.now() < 1.0  # connected while the filter still aligns (about 1 s at rest)
    args, setpoints = fly_setpoints.parse_args(
        ["--setpoint", "1", "0", "2", "--takeoff-alt", "2", "--hold", "0"]
    )

    assert fly_setpoints.fly(link, args, setpoints) == 0

    out = capsys.readouterr().out
    waits = [line for line in out.splitlines() if "waiting for the vehicle to be ready to arm: " in line]
    assert waits and "estimator not ready" in waits[0], out
    texts = [text for _, _, text in link.statustext]
    assert not any(text.startswith("arming refused") for text in texts), texts
    assert any(text.startswith("Preflight Fail: estimator not ready: ") for text in texts), texts
    ready = next(t for t, _, text in link.statustext if text == "ready to arm")
    armed = next(t for t, _, text in link.statustext if text == "armed")
    assert 1.0 < ready <= armed < ready + 2.0  # armed once ready, after the filter's first second
    assert "disarmed" in texts[-1] and not stack.autopilot.commander.armed
    assert stack.sim.plant.truth().position_m[2] < 0.05  # on the ground


def test_the_wait_fails_with_the_reason_when_the_vehicle_never_becomes_armable(tmp_path) -> None:
    """An EKF without a heading source (EKF2_MAG_TYPE 5, none, and no vision) never aligns: the
    wait ends after its timeout (simulation time) with the vehicle's reason, not a bare refusal."""
    params = tmp_path / "params.toml"
    params.write_text("EKF2_MAG_TYPE = 5\n")
    stack = make_stack(sensors="gps", estimator="ekf", params_file=str(params))
    link = connect(stack)
    reason = r"estimator not ready: aligning: waiting for a heading source \(magnetometer, or vision yaw\)"
    expected = rf"after 5 s of simulation time .*ready to arm.*: no position \({reason}\)$"
    with pytest.raises(LinkTimeout, match=expected):
        link.arm_when_ready(sim_timeout_s=5.0)
    assert 5.0 < link.now() < 7.0
    assert not stack.autopilot.commander.armed
