"""The whole simulator as a step machine: the plant's side of lockstep, without sockets or clocks.

:class:`SimulatorCore` owns simulation time, the coupled plant, the disturbance schedule (and
uploads to it), the sensor models, the frame encoder, the answer decoder and the emergency descent
flown when the autopilot is lost. One lockstep period is two calls:

1. :meth:`~SimulatorCore.begin_frame` ``() -> datagram``: the truth and sensor readings at the
   frame's time ``t = k / control_hz`` as ONE datagram (HIL_SENSOR, HIL_STATE_QUATERNION, ODOMETRY,
   HIL_GPS at the GPS rate and BATTERY_STATUS at the battery monitor's, all stamped
   ``time_usec = round(k * 1e6 / control_hz)``); the
   frame's truth row (with the disturbance applied at ``t``) is :attr:`~SimulatorCore.truth_row`;
   If no answer comes within :attr:`~SimulatorCore.resend_after_s` (wall time in the process,
   simulation time in-process), :meth:`~SimulatorCore.resend_frame` gives the same datagram again
   (counted): a lost frame or answer costs one resend, not the lockstep timeout;
2. :meth:`~SimulatorCore.end_frame` ``(answer)``: apply the autopilot's HIL_ACTUATOR_CONTROLS for
   that frame (zero unless armed, consistent and finite) or, while the autopilot is lost, the
   emergency descent; then step the plant ``physics_hz / control_hz`` times by RK4, evaluating the
   disturbance at every physics step.

Between the two, whoever couples the core to an autopilot delivers the datagram and finds the
answer (:meth:`~SimulatorCore.answer_to_frame` picks it out of any datagram): the simulator
process over UDP with a wall-clock timeout and pacing (:mod:`simulator.app`), the in-process
runner by calling the autopilot's core directly (:mod:`sitl.inprocess`), with the frame's
messages unframed (:meth:`~SimulatorCore.begin_frame_parts`: the payloads the autopilot reads of
the datagram) and the answer likewise. That is the one lockstep loop; both paths run it, so their
trajectories are identical.

The autopilot's requests to the simulator ride in the answer (:mod:`quadcommon.wire`):
:meth:`~SimulatorCore.end_frame` takes those of the answer it applies, once, and carries them out
from the next frame on (:meth:`~SimulatorCore.inject_failure`: a sensor, a rotor, the battery).
The scenario's motor failures at a time (``[[actuator_faults]]``) apply at the start of the first
frame at or after their time, through the plant's fault table (the kernels the campaigns fly).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from quadcommon import failures, wire
from quadcommon.config import (
    ScenarioConfig,
    SitlConfig,
    VehicleConfig,
    apply_uncertainty,
    load_scenario,
    load_sitl,
    load_vehicle,
)
from quadcommon.mavlink_fast import MessageParts
from quadcommon.wire import LockstepAnswer, new_parser, restart_parser
from quadcommon.wire_values import frame_time_usec

from .battery import BatteryModel
from .dynamics.plant import HEALTHY, RotorFault, make_plant, motors_of, rotor_of_motor, schedule
from .environment.gust_profile import DisturbanceSchedule, GustProfile, load_gust_profile
from .environment.gust_upload import handle_gust_request
from .mavlink.hil import (
    ActuatorAnswer,
    ActuatorDecoder,
    HilFrameEncoder,
    InjectFailure,
    Request,
    RequestDecoder,
    SetSimParameter,
)
from .safety import MOTORS_OFF, emergency_descent, touched_down
from .sensors import SensorConfig, SensorSuite, load_sensors
from .sensors.frame import DELIVERY
from .truth_bus import truth_row

Controls = tuple[float, float, float, float]
MAX_HELLO_BYTES = 2048  # parsed of a would-be peer's datagram


class PlantDiverged(RuntimeError):
    """The plant's state is no longer finite (the closed loop blew up)."""


@dataclass(frozen=True)
class SimulatorSetup:
    """What one simulator is: configuration loaded and validated, nothing running."""

    sitl: SitlConfig
    scenario: ScenarioConfig
    vehicle: VehicleConfig
    sensors: SensorConfig
    gusts: GustProfile  # applied from t = 0
    instance: int = 0
    nominal_plant: bool = False  # fly the Section II model (checks of the controllers' assumptions)
    # A campaign's run as drawn (sitl.campaign): the true plant (rotor constants the allocator does
    # not know included) instead of apply_uncertainty(vehicle, scenario), and an initial velocity.
    true_plant: VehicleConfig | None = None
    initial_velocity_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @classmethod
    def load(
        cls,
        instance: int = 0,
        scenario: str = "hover",
        vehicle: str | None = None,
        sitl_config: str | None = None,
        sensors: str | None = None,
    ) -> SimulatorSetup:
        """By names (config/...), as the command line gives them; ConfigError names file and key."""
        scen = load_scenario(scenario)
        return cls(
            load_sitl(sitl_config), scen, load_vehicle(vehicle or scen.vehicle),
            load_sensors(sensors or scen.sensors), load_gust_profile(scen.gusts), instance,
        )  # fmt: skip


class DisturbanceReport:
    """When a frame reports the applied disturbance (``DISTURB``, :mod:`quadcommon.wire`), and
    with which sample time: the autopilot holds the last report, so the reports alone draw the
    disturbance as applied, at a few bytes per change instead of one message a frame.

    A value is reported

    * at the first frame, and at least every ``DISTURBANCE_REPORT_EVERY_S`` (a late listener);
    * at an onset: the first frame that differs from a value that was reported and held since;
    * while it keeps changing (a ramp, a gust), at most every ``interval_us``;
    * when it settles: the first value that stays, stamped with the frame it was first applied
      (the previous one), so the end of a ramp is where it happened.
    """

    def __init__(self, interval_us: int = 10_000) -> None:
        self.interval_us = interval_us
        self._reported = None  # the last value reported, and its sample time
        self._reported_usec = 0
        self._previous = None  # the previous frame's value and time
        self._previous_usec = 0

    def due(self, time_usec: int, value: tuple) -> tuple[int, tuple] | None:
        """``(sample time, value)`` to report in the frame at ``time_usec``, or None."""
        previous, previous_usec = self._previous, self._previous_usec
        self._previous, self._previous_usec = value, time_usec
        reported = self._reported
        if value == reported:  # steady and known: a reminder now and then
            if time_usec - self._reported_usec < 1e6 * wire.DISTURBANCE_REPORT_EVERY_S:
                return None
            stamp = time_usec
        elif reported is None or (previous == reported and self._reported_usec < previous_usec):
            # the first frame, or an onset: a change after a value held (and reported) for a while
            stamp = time_usec
        elif value == previous:  # settled on a value not reported yet: it applied since then
            stamp = previous_usec
        elif time_usec - self._reported_usec >= self.interval_us:  # still changing
            stamp = time_usec
        else:
            return None
        self._reported, self._reported_usec = value, stamp
        return stamp, value


class SimulatorCore:
    """The plant process's core, without sockets or clocks: the coupled plant, the disturbances,
    the sensors and the battery, stepped one lockstep frame at a time (:meth:`begin_frame` gives
    the frame's datagram, :meth:`answer_to_frame` takes the autopilot's answer); time comes in
    as the frame counter, the shell (:mod:`simulator.app`) paces it."""
    def __init__(self, setup: SimulatorSetup, log: Callable[[str], None] = lambda text: None) -> None:
        self.setup = setup
        self.log = log
        rates = setup.sitl.rates
        self.control_hz = rates.control_hz
        self.physics_hz = rates.physics_hz
        self.substeps = rates.physics_steps_per_control
        self.dt_control = 1.0 / rates.control_hz
        self.dt_physics = self.dt_control / self.substeps
        self.usec_per_frame = 1e6 / rates.control_hz
        vehicle = setup.vehicle
        self.wrench = vehicle.actuation.mode == "wrench"
        self.plant_vehicle = setup.true_plant or apply_uncertainty(vehicle, setup.scenario)  # what is flown
        if setup.nominal_plant:
            self.plant_vehicle = as_nominal(self.plant_vehicle)
        self.plant = make_plant(self.plant_vehicle, self.dt_physics)
        self.plant.reset(
            setup.scenario.initial_position_m, setup.scenario.initial_euler_rad, setup.initial_velocity_m_s
        )
        self.schedule = self._new_schedule(setup.gusts, 0.0)
        self._pending_schedule: DisturbanceSchedule | None = None
        self.sensors = SensorSuite(setup.sensors, setup.sitl.home[2], imu_rate_hz=rates.control_hz)
        # The flight battery and its monitor; MAV_CMD_INJECT_FAILURE reaches battery.inject_failure.
        self.battery = BatteryModel(self.plant_vehicle, setup.sitl.home[2], 1.0 / wire.BATTERY_REPORT_HZ)
        self.encoder = HilFrameEncoder(wire.system_id(setup.instance), setup.sitl.home)
        self.decoder = ActuatorDecoder()
        self.requests = RequestDecoder(wire.system_id(setup.instance))  # the autopilot's, in its answers
        self.requests_applied = 0
        self._requests_usec = -1  # the answer whose requests applied last (a copy never applies twice)
        self._late_answer: ActuatorAnswer | None = None  # its requests apply at the next end_frame
        self.failures: dict[str, str] = {}  # active injected failures: unit -> type (PX4's names)
        # The scenario's motor failures at a time, one row per motor, by onset (the plant's table).
        self._scheduled, self._fault_table = schedule(setup.scenario.actuator_faults)
        if self._scheduled and setup.nominal_plant:
            raise ValueError(f"scenario '{setup.scenario.name}': actuator_faults need the coupled plant "
                             "(the nominal Section II model has no rotors)")  # fmt: skip
        self._fault_row = 0
        self.rotor_health = HEALTHY_ROTORS  # per rotor (plant order): effectiveness x 4, failure type x 4
        self._probe = new_parser()  # for is_autopilot: never touches the lockstep decoder
        self.k = 0  # the frame being flown
        self.time_usec = 0
        self._truth_row_of: tuple = ()  # what frame k's truth row is made of (truth_row)
        self._truth_row: tuple[float, ...] | None = ()
        self.disturbance_report = DisturbanceReport()
        self._frame_payloads: dict[int, bytes] = {}  # the current frame's messages (begin_frame_parts)
        self._frame_datagram: bytes | None = b""  # ... framed (frame_datagram)
        self.resends = 0  # frames sent again for want of an answer (a lost frame or answer)
        self.resend_after_s = resend_after_s(setup.sitl)
        self.warnings: list[str] = []  # once each: for the shell's stderr
        self._warned: set[str] = set()
        # Autopilot lost: the emergency descent.
        self.emergency = False
        self.emergency_landed = False  # motors off for the rest of the outage
        self._armed = False  # the armed bit of the last applied answer
        self._lost_usec = 0  # the frame that was not answered

    @property
    def t(self) -> float:
        """Simulation time of the current frame (s)."""
        return self.k * self.dt_control

    # -- the lockstep period --------------------------------------------------------------------
    def begin_frame(self) -> bytes:
        """Frame ``k``'s datagram (:meth:`begin_frame_parts`, framed)."""
        self.begin_frame_parts()
        return self.frame_datagram

    def begin_frame_parts(self) -> MessageParts:
        """Frame ``k``'s messages, unframed: what the autopilot reads of :meth:`begin_frame`'s
        datagram, for a runner that hands the frame over in the process (the in-process stack, the
        fleet); :attr:`frame_datagram` frames them when asked. Also sets :attr:`truth_row`. Raises
        PlantDiverged when the state is not finite or too large for the wire."""
        if self._pending_schedule is not None:
            self.schedule, self._pending_schedule = self._pending_schedule, None
        k, t = self.k, self.k * self.dt_control
        self.time_usec = time_usec = frame_time_usec(k, self.usec_per_frame)
        if self._fault_row < len(self._scheduled):
            self._scheduled_faults_due(t)
        truth = self.plant.truth()
        p = truth.position_m
        if not math.isfinite(p[0] + p[1] + p[2]):
            raise PlantDiverged(f"the plant state is not finite at t={t:.3f} s")
        force, torque, wind = self.schedule.evaluate(t)
        delivery = self.sensors.deliver(t, truth)
        gps = vision = None
        if delivery[DELIVERY.gps_fresh] != 0.0 or delivery[DELIVERY.vision_fresh] != 0.0:
            sensed = self.sensors.delivered(t)  # (the readings of a fix or a pose, when one came)
            gps, vision = sensed.gps, sensed.vision
        health = self.rotor_health
        self._truth_row_of, self._truth_row = (t, truth, force, torque, wind, health), None
        report = self.disturbance_report.due(time_usec, (force, torque, health))
        battery = self.battery.frame(t, self.dt_control if k > 0 else 0.0, truth, self._armed)
        try:
            payloads = self.encoder.frame_payloads(
                time_usec, truth, delivery, wind, gps, vision, report, battery
            )
        except OverflowError as exc:  # finite but past float32: a blow-up a frame or two away
            raise PlantDiverged(f"the plant state no longer fits the wire's float32 at t={t:.3f} s") from exc
        self._frame_payloads, self._frame_datagram = payloads, None
        return MessageParts.of_payloads(payloads, wire.SIMULATOR_COMPONENT_ID)

    @property
    def frame_datagram(self) -> bytes:
        """The current frame's datagram, framed once (on the encoder's sequence) when first asked:
        a resend repeats it byte for byte."""
        if self._frame_datagram is None:
            self._frame_datagram = self.encoder.datagram(self._frame_payloads)
        return self._frame_datagram

    @property
    def truth_row(self) -> tuple[float, ...]:
        """Frame ``k``'s truth row (:func:`~.truth_bus.truth_row`), made when first read: the
        process reads it after the frame is out, while the autopilot computes its answer."""
        if self._truth_row is None:
            self._truth_row = truth_row(*self._truth_row_of)
        return self._truth_row

    def resend_frame(self) -> bytes:
        """The current frame again, unchanged (its answer is overdue: the frame or the answer was
        lost); counted in :attr:`resends`. The autopilot answers a frame it has answered already
        from that answer, without stepping again, so a resend never changes the flight."""
        self.resends += 1
        return self.frame_datagram

    def is_autopilot(self, datagram: bytes) -> bool:
        """True if ``datagram`` holds a valid MAVLink message from this vehicle's autopilot
        (system 1 + N, component 1): only such a sender becomes the lockstep peer, so a stray
        datagram to the HIL port cannot take the link over."""
        probe = self._probe
        restart_parser(probe)
        try:
            messages = probe.parse_buffer(datagram[:MAX_HELLO_BYTES]) or []
        except Exception:  # pymavlink raises on some malformed frames even when robust
            return False
        ids = (wire.system_id(self.setup.instance), wire.AUTOPILOT_COMPONENT_ID)
        return any(
            msg.get_msgId() >= 0 and (msg.get_srcSystem(), msg.get_srcComponent()) == ids for msg in messages
        )

    def answer_to_frame(self, datagram: bytes | LockstepAnswer) -> ActuatorAnswer | None:
        """The HIL_ACTUATOR_CONTROLS for the current frame in ``datagram`` (or in an answer the
        in-process runner hands over unframed), else None (a heartbeat, a late answer to an earlier
        frame, garbage)."""
        if isinstance(datagram, LockstepAnswer):
            answer = self.decoder.decode_unframed(datagram)
        else:
            answer = self.decoder.decode(datagram)
        return answer if answer is not None and answer.time_usec == self.time_usec else None

    def end_frame(self, answer: ActuatorAnswer | None) -> None:
        """Apply ``answer`` (None: the emergency descent, while lost) and step the plant; the
        answer's requests (or those of the answer that ended an outage) apply from the next frame."""
        plant = self.plant
        if self.emergency or answer is None:
            plant.set_actuator_controls(self._emergency_controls())
        else:
            plant.set_actuator_controls(self._controls(answer))
        t, dt, evaluate = self.t, self.dt_physics, self.schedule.evaluate
        plant.advance([evaluate(t + j * dt) for j in range(self.substeps)])
        self.k += 1
        carrier = answer if answer is not None else self._late_answer
        self._late_answer = None
        if carrier is not None and carrier.others:
            self._take_requests(carrier)

    # -- the autopilot's requests -----------------------------------------------------------------
    def _take_requests(self, answer: ActuatorAnswer) -> None:
        """The requests an answer carries, once: a copy of an answer that applied already (the
        answer to a resent frame) applies nothing."""
        if answer.time_usec <= self._requests_usec:
            return
        self._requests_usec = answer.time_usec
        refused = self.requests.refused_total
        for request in self.requests.decode(answer.others):
            self.apply_request(request)
        if self.requests.refused_total != refused:
            self._warn_once("request", "a request in the autopilot's answer was refused (counted by reason "
                            "in quadsitl/<N>/info: requests)")  # fmt: skip

    def apply_request(self, request: Request) -> None:
        """Carry out one request from now on (the frame :attr:`t`); one that cannot be is refused
        and counted with its reason (``info()['requests']``)."""
        if isinstance(request, InjectFailure):
            problem = self.inject_failure(request.unit, request.failure_type, request.instance,
                                          request.effectiveness)  # fmt: skip
        elif isinstance(request, SetSimParameter):
            accepted = self.set_battery_parameter(request.name, request.value)
            problem = None if accepted else f"PARAM_SET {request.name} = {request.value:g} refused"
        else:  # pragma: no cover - every Request type has its branch
            problem = f"request {request!r} not handled"
        if problem is None:
            self.requests_applied += 1
        else:
            self.requests.refuse(problem)  # one count of the refusals on the channel

    def inject_failure(
        self, unit: int, failure_type: int, instance: int, effectiveness: float = 1.0
    ) -> str | None:
        """``MAV_CMD_INJECT_FAILURE`` (:mod:`quadcommon.failures`) from the current frame on: a
        sensor of the sensor models, a rotor of the plant (PX4's motor numbers; ``effectiveness``
        what a ``wrong`` one keeps, in [0, 1]), the battery model. None when applied, else why
        not."""
        refusal = failures.refusal(unit, failure_type, instance)
        if refusal is not None:
            return refusal[1]
        model = failures.FAILURES[failures.Unit(unit)]
        name, type_name = model.unit.name, failures.Type(failure_type).name
        where = model.where
        if where is failures.Where.SENSORS:
            self.sensors.inject_failure(name, failure_type, self.t)
        elif where is failures.Where.PLANT:
            if self.setup.nominal_plant:
                return f"failure {name}: the nominal plant (the Section II model) has no rotors"
            try:
                fault = RotorFault.of(failure_type, effectiveness)
            except ValueError as exc:
                return f"failure {name} {type_name}: {exc}"
            for motor in motors_of(instance):  # PX4's numbers: the rotor at the same position
                self.plant.set_rotor_fault(rotor_of_motor(motor), fault)
            self._rotor_health_changed()
        elif where is failures.Where.BATTERY:
            if not self.battery.inject_failure(failure_type):
                return f"failure {name} {type_name}: refused by the battery model"
        else:
            return f"failure {name}: the autopilot's own (its links), not the simulator's"
        failures.keep_active(self.failures, unit, failure_type, instance)
        self.log(f"t={self.t:.3f} s: {failures.announcement(unit, failure_type, instance)}")
        return None

    def _scheduled_faults_due(self, t: float) -> None:
        """The scenario's motor failures whose time has come, into the plant (at frame ``t``)."""
        row = self.plant.faults_due(self._fault_table, self._fault_row, t)
        for fault, motor in self._scheduled[self._fault_row : row]:
            failures.keep_active(self.failures, failures.Unit.motor, fault.failure_type, motor)
            text = failures.announcement(failures.Unit.motor, fault.failure_type, motor)
            self.log(f"t={t:.3f} s: {text} (scenario, from {fault.start_s:g} s)")
        self._fault_row = row
        self._rotor_health_changed()

    def _rotor_health_changed(self) -> None:
        """:attr:`rotor_health` again, from the plant's rotors (plant order: 1 front, 2 right,
        3 rear, 4 left): their effectiveness, then their FAILURE_TYPE (0 healthy)."""
        faults = [self.plant.rotor_fault(rotor) for rotor in (1, 2, 3, 4)]
        self.rotor_health = (*(f.effectiveness for f in faults), *(float(f.failure_type) for f in faults))

    def _controls(self, answer: ActuatorAnswer) -> Controls:
        """Zero unless armed, consistent with our actuation and finite."""
        self._armed = answer.armed
        if answer.wrench != self.wrench:
            mode = "wrench" if answer.wrench else "rotors"
            v = self.setup.vehicle
            self._warn_once(
                "actuation",
                f"refusing HIL_ACTUATOR_CONTROLS: their flags say actuation '{mode}' but vehicle "
                f"'{v.name}' has actuation '{v.actuation.mode}'; motors off. "
                "Start both processes with the same --vehicle.",
            )
            return MOTORS_OFF
        if not answer.lockstep:
            self._warn_once("lockstep", "HIL_ACTUATOR_CONTROLS without the lockstep flag (bit 0); accepted")
        if not answer.armed:
            return MOTORS_OFF
        c = answer.controls
        if not math.isfinite(c[0] + c[1] + c[2] + c[3]):
            self._warn_once("finite", f"non-finite actuator controls {c}; motors off for those frames")
            return MOTORS_OFF
        return c

    def _warn_once(self, key: str, text: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            self.warnings.append(text)

    # -- autopilot lost -------------------------------------------------------------------------
    def autopilot_lost(self) -> None:
        """The current frame got no answer in time: fly the emergency descent from now on."""
        self.emergency = True
        self._lost_usec = self.time_usec
        truth = self.plant.truth()
        if not self._armed or touched_down(truth):
            self.emergency_landed = True
            what = "disarmed" if not self._armed else "on the ground"
            self.log(f"autopilot lost: vehicle {what}, motors off; waiting for the autopilot to answer again")
        else:
            self.emergency_landed = False
            self.log(
                f"autopilot lost: emergency descent from z={truth.position_m[2]:.2f} m at 0.5 m/s "
                "(levelled; motors off on touchdown); waiting for the autopilot to answer again"
            )

    def answers_again(self, datagram: bytes) -> bool:
        """While lost: True if ``datagram`` answers the missed frame or a later one (the autopilot
        may be catching up on queued frames); lockstep then resumes from the next frame."""
        answer = self.decoder.decode(datagram)
        if answer is None or answer.time_usec < self._lost_usec:
            return False
        self._late_answer = answer
        self.emergency = self.emergency_landed = False
        self.log(f"link recovered: the autopilot answers again; resuming lockstep at t={self.t:.3f} s")
        return True

    def _emergency_controls(self) -> Controls:
        if self.emergency_landed:
            return MOTORS_OFF
        truth = self.plant.truth()
        if touched_down(truth):
            self.emergency_landed = True
            self.log(f"emergency descent: touchdown at t={self.t:.3f} s, motors off")
            return MOTORS_OFF
        return emergency_descent(truth, self.plant_vehicle).controls

    # -- gusts ----------------------------------------------------------------------------------
    def schedule_gust_profile(self, profile: GustProfile, start_time_s: float) -> None:
        """Replace the disturbance schedule by ``profile`` from ``start_time_s`` (s, simulation).

        Takes effect at the next frame boundary, so a frame's truth row and its physics steps
        always see one schedule.
        """
        self._pending_schedule = self._new_schedule(profile, start_time_s)
        self.log(f"gust profile uploaded: applies from t={start_time_s:.3f} s")

    def upload_gusts(self, payload: bytes) -> tuple[bool, bytes]:
        """A gust-profile upload request (``quadsitl/<N>/sim/gusts``, JSON; protocol in
        :mod:`.environment.gust_upload`): validated, installed from its start time; the reply says
        accepted with the absolute start time (and a warning for wind without drag), or why not."""
        ok, reply, profile, start_s = handle_gust_request(payload, self.t, self.dt_physics)
        if not ok:
            return False, reply
        self.schedule_gust_profile(profile, start_s)  # type: ignore[arg-type]
        note = self.wind_warning(profile)  # type: ignore[arg-type]
        if note:
            reply = json.dumps({**json.loads(reply), "warning": note}).encode()
        return True, reply

    def wind_warning(self, profile: GustProfile) -> str | None:
        """Wind acts through drag only: say so when this vehicle has none."""
        has_wind = bool(profile.one_minus_cosine) or profile.dryden is not None
        vehicle = self.setup.vehicle
        if has_wind and not any(vehicle.plant.drag_coefficient_n_s_m):
            return (
                f"vehicle '{vehicle.name}' has zero drag (plant.drag_coefficient_n_s_m), so wind "
                "gusts and turbulence have no effect; use a vehicle with drag, e.g. paper_quad_drag"
            )
        return None

    # -- the battery ----------------------------------------------------------------------------
    def set_battery_parameter(self, name: str, value: float) -> bool:
        """A PX4 battery-simulator parameter from the autopilot (``SIM_BAT_ENABLE``,
        ``SIM_BAT_DRAIN``, ``SIM_BAT_MIN_PCT``): validated, applied from the next battery report;
        False (nothing changed) for another name or a value out of PX4's range."""
        accepted = self.battery.set_parameter(name, value)
        if accepted:
            self.log(f"battery: {name} = {value:g}")
        return accepted

    def _new_schedule(self, profile: GustProfile, start_time_s: float) -> DisturbanceSchedule:
        """The one place schedules are built: evaluated at every physics step, in non-decreasing
        time (the Dryden turbulence samples at ``step_s`` and only runs forward)."""
        return DisturbanceSchedule(profile, start_time_s, step_s=self.dt_physics)

    def info(self) -> dict[str, Any]:
        """What ``quadsitl/<N>/info`` answers (the shell adds its speed)."""
        setup = self.setup
        return {
            "instance": setup.instance,
            "vehicle": setup.vehicle.name,
            "scenario": setup.scenario.name,
            "actuation": setup.vehicle.actuation.mode,
            "physics_hz": self.physics_hz,
            "control_hz": self.control_hz,
            "home": list(setup.sitl.home),  # lat deg, lon deg, alt m: where its local frame is
            "sim_time_s": self.t,
            "resends": self.resends,
            "battery": self.battery.info(),
            "failures": dict(self.failures),
            "requests": {"applied": self.requests_applied, "refused": dict(self.requests.refused)},
        }


HEALTHY_ROTORS = (*(HEALTHY.effectiveness,) * 4, *(float(HEALTHY.failure_type),) * 4)


def resend_after_s(sitl: SitlConfig) -> float:
    """How long (s) an unanswered frame waits before it is sent again: ``[lockstep] resend_s``
    plus the HIL link's impairment round trip (delay and jitter both ways), so a frame that is
    merely delayed is not resent."""
    return sitl.lockstep_resend_s + 2.0 * sitl.impair.hil.latest_s


def as_nominal(vehicle: VehicleConfig) -> VehicleConfig:
    """The vehicle flown as the Section II model: no CoM offset, no crossed inertia, wrench."""
    from dataclasses import replace

    plant = replace(
        vehicle.plant,
        model="nominal",
        com_offset_m=(0.0, 0.0, 0.0),
        products_of_inertia_kg_m2=(0.0, 0.0, 0.0),
    )
    return replace(vehicle, plant=plant, actuation=replace(vehicle.actuation, mode="wrench"))
