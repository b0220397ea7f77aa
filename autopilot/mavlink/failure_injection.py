"""``MAV_CMD_INJECT_FAILURE`` as PX4 handles it: the command, the active failures, the links.

What can fail and how is :mod:`quadcommon.failures` (one table). The command is answered as PX4
answers it:

* ``DENIED`` while ``SYS_FAILURE_EN`` is 0 (PX4's MAVLink receiver refuses it then), with the
  reason in a STATUSTEXT;
* ``UNSUPPORTED`` for a (unit, type) the table does not model; ``DENIED`` for an instance the
  unit does not have, for a motor's effectiveness (param4) outside [0, 1], and for a sensor
  failure while the vehicle flies on the simulator's state (``EKF2_EN`` 0: it does not fly on its
  sensors, so a sensor failure would change nothing it uses: start with ``--estimator ekf``);
* ``TEMPORARILY_REJECTED`` while too many requests wait for the simulator (PX4's answer when its
  table of failures is full);
* ``ACCEPTED`` otherwise, announced by STATUSTEXT as PX4 words it (``Injected: gps off, all
  instances``, ``Cleared: gps, all instances``; the flight log keeps it with every STATUSTEXT).

A failure of the simulator's (sensors, plant, battery) travels to it as a request in the next
lockstep answer (:class:`~.hil.SimulatorRequests`, :mod:`quadcommon.wire`): the vehicle learns of
it from its data only. A motor's ``wrong`` (a loss of effectiveness) travels with the
effectiveness it leaves: the command's param4 when in (0, 1], else ``SIM_MOT_EFF``. The links'
own failures (``rc_signal``, ``mavlink_signal``) act here, as PX4's receiver: every
``MANUAL_CONTROL`` dropped (the manual-control loss failsafe, ``NAV_RCL_ACT``), every message from
the ground stations dropped (their heartbeats too: the data-link loss failsafe, ``NAV_DLL_ACT``) but
``MAV_CMD_INJECT_FAILURE`` itself, which still passes so that the recovery (``ok``) can reach the
vehicle; the vehicle keeps sending.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from quadcommon.failures import (
    ALL_INSTANCES,
    FAILURES,
    MOTOR_EFFECTIVENESS_PARAMETER,
    Refusal,
    Type,
    Unit,
    Where,
    announcement,
    keep_active,
    motor_effectiveness,
    refusal,
)

from ..params.store import ParameterStore
from .codec import mavlink as m

Result = tuple[int, str]
DISABLED = "failure injection disabled: set SYS_FAILURE_EN to 1"


class FailureInjection:
    """The autopilot's failure injection: answers the command, keeps the active failures, drops
    the links' messages while their failure is active.

    ``to_simulator(unit, type, instance, effectiveness)`` queues the request for the simulator
    (False: the queue is full, answered TEMPORARILY_REJECTED); ``flying_on_ekf()`` says whether the
    vehicle flies on its EKF; ``refuse(text)`` and ``announce(severity, text)`` send STATUSTEXT (the first
    rate-limited)."""

    def __init__(
        self,
        params: ParameterStore,
        to_simulator: Callable[[int, int, int, float], bool],
        flying_on_ekf: Callable[[], bool],
        refuse: Callable[[str], None],
        announce: Callable[[int, str], None],
    ) -> None:
        self.params = params
        self.to_simulator = to_simulator
        self.flying_on_ekf = flying_on_ekf
        self.refuse = refuse
        self.announce = announce
        self.active: dict[str, str] = {}  # unit (and instance) -> type, PX4's names
        self.rc_signal_lost = False
        self.mavlink_signal_lost = False
        self.dropped: dict[str, int] = {}  # messages dropped by a link's failure, by unit

    # -- the command ------------------------------------------------------------------------------
    def command(self, unit: int, failure_type: int, instance: float, param4: float = math.nan) -> Result:
        """``MAV_CMD_INJECT_FAILURE`` (parameters validated as bytes; instance NaN: all; ``param4``
        a motor's effectiveness under ``wrong``, 0 or NaN: ``SIM_MOT_EFF``)."""
        if self.params["SYS_FAILURE_EN"] != 1.0:
            return self._refused(m.MAV_RESULT_DENIED, DISABLED)
        number = ALL_INSTANCES if math.isnan(instance) else int(instance)
        why = refusal(unit, failure_type, number)
        if why is not None:
            kind, text = why
            result = m.MAV_RESULT_UNSUPPORTED if kind is Refusal.UNSUPPORTED else m.MAV_RESULT_DENIED
            return self._refused(result, text)
        model = FAILURES[Unit(unit)]
        name = model.unit.name
        effectiveness = 1.0
        if model.where is Where.PLANT:
            left = motor_effectiveness(failure_type, param4, self.params[MOTOR_EFFECTIVENESS_PARAMETER])
            if left is None:
                return self._refused(m.MAV_RESULT_DENIED, (
                    f"failure {name}: effectiveness (param4) {param4:g} outside [0, 1] (0 or NaN: "
                    f"{MOTOR_EFFECTIVENESS_PARAMETER})"))  # fmt: skip
            effectiveness = left
        if model.where is Where.SENSORS and failure_type != Type.ok and not self.flying_on_ekf():
            return self._refused(m.MAV_RESULT_DENIED, (
                f"failure {name} acts on the EKF: this vehicle flies on the simulator's state (EKF2_EN 0); "
                "start it with --estimator ekf (EKF2_EN 1)"))  # fmt: skip
        if model.where is Where.AUTOPILOT:
            lost = failure_type != Type.ok
            if model.unit is Unit.rc_signal:
                self.rc_signal_lost = lost
            else:
                self.mavlink_signal_lost = lost
        elif not self.to_simulator(unit, failure_type, number, effectiveness):
            return self._refused(m.MAV_RESULT_TEMPORARILY_REJECTED, "failure injection: too many requests "
                                 "waiting for the simulator; try again")  # fmt: skip
        keep_active(self.active, unit, failure_type, number)
        self.announce(m.MAV_SEVERITY_WARNING, announcement(unit, failure_type, number))
        return m.MAV_RESULT_ACCEPTED, ""

    def _refused(self, result: int, reason: str) -> Result:
        self.refuse(reason)
        return result, reason

    def simulator_restarted(self) -> None:
        """A new simulator has none of the failures the old one carried."""
        simulator_units = {u.name for u, model in FAILURES.items() if model.where is not Where.AUTOPILOT}
        self.active = {k: v for k, v in self.active.items() if k.split()[0] not in simulator_units}

    # -- the links --------------------------------------------------------------------------------
    def drops(self, msg) -> bool:
        """True when a link's failure drops ``msg`` (a ground station's message), counted."""
        if self.mavlink_signal_lost:
            if msg.get_msgId() in (m.MAVLINK_MSG_ID_COMMAND_LONG, m.MAVLINK_MSG_ID_COMMAND_INT) and (
                getattr(msg, "command", None) == m.MAV_CMD_INJECT_FAILURE
            ):
                return False  # the recovery still gets through
            self._count(Unit.mavlink_signal.name)
            return True
        if self.rc_signal_lost and msg.get_msgId() == m.MAVLINK_MSG_ID_MANUAL_CONTROL:
            self._count(Unit.rc_signal.name)
            return True
        return False

    def _count(self, unit: str) -> None:
        self.dropped[unit] = self.dropped.get(unit, 0) + 1

    def info(self) -> dict:
        """The counters for ``quadsitl/<N>/autopilot/info``: whether SYS_FAILURE_EN allows injection, the
        active failures (PX4's unit and type names) and the messages the links' failures dropped."""
        return {"enabled": self.params["SYS_FAILURE_EN"] == 1.0, "active": dict(self.active),
                "dropped": dict(self.dropped)}  # fmt: skip
