"""The flight battery: a LiPo pack, what the rotors draw from it, and the monitor that reports it.

Pure: no clock, no I/O; the simulator core calls :meth:`BatteryModel.frame` once per lockstep
frame with the frame's truth, and puts what the monitor reports into the frame
(``BATTERY_STATUS``, :mod:`quadcommon.wire`).

**The pack** (``SIM_BAT_DRAIN`` = 0, the default). ``N`` cells in series, capacity ``C`` (mAh),
state of charge ``s`` in [0, 1] (the vehicle's ``[battery]``):

* open-circuit voltage per cell ``E(s)``: a LiPo cell's resting voltage against its charge
  (:data:`LIPO_OCV_V`, the curve RC users tabulate, 4.20 V full, 3.27 V empty), linear between
  its points every 5 %;
* internal resistance ``R`` (the whole pack's): the terminal voltage sags with the current,
  ``V = N E(s) - R I``;
* the current delivers the power drawn, ``P = V I = (N E - R I) I``, the smaller root
  ``I = (N E - sqrt((N E)^2 - 4 R P)) / (2 R)``; past the pack's greatest power
  ``(N E)^2 / (4 R)`` the current is that point's, ``N E / (2 R)`` (the voltage has halved);
* charge: ``ds/dt = -I / (3.6 C)`` (``C`` mAh is ``3.6 C`` coulombs), ``s`` stops at 0.

The pack feeds nothing back into the flight: the rotors keep their speeds at any voltage (the
speed controllers are assumed to have the headroom), a flat pack included.

**The power drawn**: the shaft power over the motors' and speed controllers' efficiency ``eta``,
plus the avionics (flight controller, receiver, GPS; a constant ``P_avionics``):

* ``actuation = "rotors"``: each rotor's aerodynamic torque ``d Omega^2`` at its speed (the
  plant's rotor model, :mod:`simulator.dynamics.plant`): ``P_shaft = d sum |Omega_i|^3``;
* ``actuation = "wrench"`` (the paper's idealised actuator, no rotor speeds): momentum theory.
  Each of the four rotors carries ``T / 4``; a rotor of disc area ``A = pi r^2`` in air of
  density ``rho`` needs the ideal induced power ``(T/4)^(3/2) / sqrt(2 rho A)``, and a real one
  that over its figure of merit ``FM``: ``P_shaft = 4 (T/4)^(3/2) / (FM sqrt(2 rho A))``
  (Leishman, *Principles of Helicopter Aerodynamics*, ch. 2-3), ``rho`` the ISA density at the
  home's altitude. The torques' share is neglected (they are small against the thrust's in
  hover and cruise). Both power laws grow as ``T^(3/2)``; the paper's vehicles pick ``r`` and
  ``FM`` so the wrench vehicle draws what the rotor model of the same airframe draws.

**PX4's battery simulator** (``SIM_BAT_DRAIN`` > 0, as PX4's ``battery_simulator``): while
armed the charge falls linearly, from full to empty in ``SIM_BAT_DRAIN`` seconds, and stops at
``SIM_BAT_MIN_PCT``; disarmed, the pack is full again. The voltage runs linearly between the
vehicle's empty and charged cell voltages (PX4's ``BAT1_V_EMPTY``, ``BAT1_V_CHARGED``) and carries
no sag; no current is measured (PX4's simulator reports -1, unknown). ``SIM_BAT_ENABLE`` = 0:
the monitor reports nothing (the pack model runs on).

The model advances at the monitor's rate (:data:`quadcommon.wire.BATTERY_REPORT_HZ`): each frame
adds its power (the thrust held over the frame just flown, or the rotor speeds at its end) and
its armed time; at a report the charge steps with the interval's mean power. Deterministic
(simulation time in), and cheap: a few float operations a frame, a square root a report.

**Failures** (:meth:`BatteryModel.inject_failure`, MAVLink ``FAILURE_TYPE``, for
``MAV_CMD_INJECT_FAILURE`` with ``FAILURE_UNIT_SYSTEM_BATTERY``) change what the monitor reports,
not the pack:

* ``OK``: the monitor reports the pack again;
* ``OFF``: the pack reads empty, its cells at the empty voltage and no current measured (as PX4's
  battery simulator takes ``off``: it has no current sensor, so no load correction lifts the
  reading back up): the autopilot's estimate falls within seconds and its low-battery failsafes
  follow;
* ``STUCK``: the monitor repeats the reading it had when the failure came;
* ``GARBAGE``: the monitor's readings are not numbers (a broken converter): they cross the wire
  as MAVLink's "unknown", which the autopilot refuses, so it hears no battery;
* ``WRONG``: the voltage divider reads 10 % high (a mis-calibrated ``BAT1_V_DIV``): the pack
  looks fuller than it is, and a full one over-voltage;
* ``SLOW``, ``DELAYED``, ``INTERMITTENT``: refused (False).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from pymavlink.dialects.v20 import common as mavlink

from quadcommon.atmosphere import isa_pressure_hpa, isa_temperature_c
from quadcommon.config import SIM_BATTERY_PARAMETERS, BatteryConfig, VehicleConfig

# A LiPo cell's open-circuit (resting) voltage, V, at 0 %, 5 %, ..., 100 % state of charge.
LIPO_OCV_V = (3.27, 3.61, 3.69, 3.71, 3.73, 3.75, 3.77, 3.79, 3.80, 3.82, 3.84,
              3.85, 3.87, 3.91, 3.95, 3.98, 4.02, 4.08, 4.11, 4.15, 4.20)  # fmt: skip
_OCV_STEPS = len(LIPO_OCV_V) - 1
AIR_GAS_CONSTANT_J_KG_K = 287.05
MAH_TO_COULOMB = 3.6
WRONG_VOLTAGE_SCALE = 1.1  # FAILURE_TYPE_WRONG: the divider reads 10 % high
ROTORS = 4

FAILURE_OK = mavlink.FAILURE_TYPE_OK
FAILURE_OFF = mavlink.FAILURE_TYPE_OFF
FAILURE_STUCK = mavlink.FAILURE_TYPE_STUCK
FAILURE_GARBAGE = mavlink.FAILURE_TYPE_GARBAGE
FAILURE_WRONG = mavlink.FAILURE_TYPE_WRONG
FAILURES = {FAILURE_OK: "ok", FAILURE_OFF: "off (reads empty)", FAILURE_STUCK: "stuck",
            FAILURE_GARBAGE: "garbage", FAILURE_WRONG: "wrong (voltage 10 % high)"}  # fmt: skip

SIM_BAT_ENABLE, SIM_BAT_DRAIN = "SIM_BAT_ENABLE", "SIM_BAT_DRAIN"  # (and SIM_BAT_MIN_PCT)


def cell_ocv_v(state_of_charge: float) -> float:
    """A LiPo cell's open-circuit voltage (V) at ``state_of_charge`` (0-1, clamped)."""
    x = min(max(state_of_charge, 0.0), 1.0) * _OCV_STEPS
    i = min(int(x), _OCV_STEPS - 1)
    return LIPO_OCV_V[i] + (x - i) * (LIPO_OCV_V[i + 1] - LIPO_OCV_V[i])


def pack_current_a(open_circuit_v: float, resistance_ohm: float, power_w: float) -> float:
    """The current (A) that draws ``power_w`` from a source of ``open_circuit_v`` behind
    ``resistance_ohm``: the smaller root of ``R I^2 - E I + P = 0``, or, past the greatest power
    ``E^2 / (4 R)``, the current of that point, ``E / (2 R)``."""
    if power_w <= 0.0:
        return 0.0
    if resistance_ohm <= 0.0:
        return power_w / open_circuit_v
    discriminant = open_circuit_v * open_circuit_v - 4.0 * resistance_ohm * power_w
    if discriminant <= 0.0:
        return open_circuit_v / (2.0 * resistance_ohm)
    return (open_circuit_v - math.sqrt(discriminant)) / (2.0 * resistance_ohm)


def air_density_kg_m3(altitude_amsl_m: float) -> float:
    """ISA air density (kg/m^3) at ``altitude_amsl_m``: ``rho = p / (R T)``."""
    kelvin = isa_temperature_c(altitude_amsl_m) + 273.15
    return 100.0 * isa_pressure_hpa(altitude_amsl_m) / (AIR_GAS_CONSTANT_J_KG_K * kelvin)


def momentum_power_coefficient(battery: BatteryConfig, air_density: float) -> float:
    """``k`` of the wrench vehicle's shaft power ``P = k T^(3/2)`` (W per N^(3/2)): four rotors
    of ``T/4`` each, momentum theory over the figure of merit (see the module's docstring)."""
    area = math.pi * battery.rotor_radius_m**2
    return ROTORS * ROTORS**-1.5 / (battery.figure_of_merit * math.sqrt(2.0 * air_density * area))


class BatteryReading(NamedTuple):
    """What the battery monitor reports (a power module): NaN where it has no number."""

    voltage_v: float  # across the pack's terminals
    current_a: float  # drawn from the pack; NaN: not measured (PX4's drain simulation)


class PackState(NamedTuple):
    """The pack's truth at the last report (for tests and analysis; the autopilot sees only the
    monitor's :class:`BatteryReading`)."""

    time_s: float
    state_of_charge: float  # 0-1
    open_circuit_v: float  # the whole pack's
    terminal_v: float
    current_a: float
    power_w: float  # electrical, drawn over the last report interval (mean)
    charge_drawn_c: float  # coulombs drawn since the start


class BatteryModel:
    """One vehicle's pack and monitor; :meth:`frame` once per lockstep frame."""

    def __init__(self, vehicle: VehicleConfig, home_altitude_m: float, report_interval_s: float) -> None:
        self.config = battery = vehicle.battery
        self.report_interval_s = report_interval_s
        self.cells = battery.cells
        self.capacity_c = battery.capacity_mah * MAH_TO_COULOMB
        self.resistance_ohm = battery.internal_resistance_ohm
        self.avionics_w = battery.avionics_power_w
        self.efficiency = battery.motor_efficiency
        self.rotor_mode = vehicle.actuation.mode == "rotors"
        self.rotor_drag = vehicle.rotors.drag_coefficient_n_m_s2
        self.momentum_k = momentum_power_coefficient(battery, air_density_kg_m3(home_altitude_m))
        # The PX4 parameters (set_parameter), from the vehicle's file until a parameter arrives.
        self.enabled = battery.enabled
        self.drain_s = battery.drain_s
        self.drain_min = battery.drain_min_pct / 100.0
        self.failure = FAILURE_OK
        self.state_of_charge = battery.initial_charge
        self.charge_drawn_c = 0.0
        self._energy_j = 0.0  # shaft power x time of the frames since the last report
        self._elapsed_s = 0.0
        self._armed_s = 0.0
        self._next_report_s = 0.0
        self._stuck: BatteryReading | None = None
        self.truth = self._pack_state(0.0, 0.0, 0.0)
        self.reading = self._measured()

    # -- the lockstep frame ---------------------------------------------------------------------
    def frame(self, t_s: float, dt_s: float, truth, armed: bool) -> BatteryReading | None:
        """Account for the frame just flown (``dt_s`` long, ending at ``t_s``; ``truth``: the
        plant's :class:`~simulator.dynamics.plant.TruthState` at ``t_s``, ``armed``: the motors'
        state over it); at a report time (every :attr:`report_interval_s`), advance the pack and
        return what the monitor reports, else None (also None while ``SIM_BAT_ENABLE`` is 0)."""
        if dt_s > 0.0:
            if self.rotor_mode:
                w = truth.rotor_speeds_rad_s
                shaft = self.rotor_drag * (abs(w[0]) ** 3 + abs(w[1]) ** 3 + abs(w[2]) ** 3 + abs(w[3]) ** 3)
            else:
                thrust = truth.thrust_n
                shaft = self.momentum_k * thrust * math.sqrt(thrust) if thrust > 0.0 else 0.0
            self._energy_j += shaft * dt_s
            self._elapsed_s += dt_s
            if armed:
                self._armed_s += dt_s
        if t_s + 1e-9 < self._next_report_s:
            return None
        self._next_report_s += self.report_interval_s
        if self._next_report_s <= t_s:  # a late start: report from now on, at the rate
            self._next_report_s = t_s + self.report_interval_s
        self._advance(t_s, armed)
        return self.reading if self.enabled else None

    def _advance(self, t_s: float, armed: bool) -> None:
        elapsed, energy, armed_s = self._elapsed_s, self._energy_j, self._armed_s
        self._elapsed_s = self._energy_j = self._armed_s = 0.0
        if self.drain_s > 0.0:  # PX4's battery simulator
            soc = self.state_of_charge - armed_s / self.drain_s if armed else 1.0
            self.state_of_charge = max(soc, self.drain_min)
            self.truth = self._pack_state(t_s, 0.0, 0.0)
        else:
            power = (energy / self.efficiency / elapsed if elapsed > 0.0 else 0.0) + self.avionics_w
            ocv = self.cells * cell_ocv_v(self.state_of_charge)
            current = pack_current_a(ocv, self.resistance_ohm, power)
            self.charge_drawn_c += current * elapsed
            self.state_of_charge = max(self.state_of_charge - current * elapsed / self.capacity_c, 0.0)
            # The voltage reported at this instant: the pack after the interval, at its current.
            self.truth = self._pack_state(t_s, current, power)
        self.reading = self._measured()

    def _pack_state(self, t_s: float, current_a: float, power_w: float) -> PackState:
        if self.drain_s > 0.0:
            b = self.config
            cell = b.empty_cell_v + self.state_of_charge * (b.charged_cell_v - b.empty_cell_v)
            ocv = terminal = self.cells * cell
        else:
            ocv = self.cells * cell_ocv_v(self.state_of_charge)
            terminal = ocv - self.resistance_ohm * current_a
        return PackState(t_s, self.state_of_charge, ocv, terminal, current_a, power_w, self.charge_drawn_c)

    def _measured(self) -> BatteryReading:
        """The monitor's reading of the pack's truth, through the injected failure."""
        truth = self.truth
        current = truth.current_a if self.drain_s <= 0.0 else math.nan
        failure = self.failure
        if failure == FAILURE_OK:
            return BatteryReading(truth.terminal_v, current)
        if failure == FAILURE_OFF:
            return BatteryReading(self.cells * self.config.empty_cell_v, math.nan)
        if failure == FAILURE_STUCK:
            assert self._stuck is not None
            return self._stuck
        if failure == FAILURE_GARBAGE:
            return BatteryReading(math.nan, math.nan)
        return BatteryReading(truth.terminal_v * WRONG_VOLTAGE_SCALE, current)  # FAILURE_WRONG

    def info(self) -> dict:
        """The pack's truth and the monitor's settings (``quadsitl/<N>/info``)."""
        truth = self.truth
        return {
            "state_of_charge": truth.state_of_charge,
            "voltage_v": truth.terminal_v,
            "current_a": truth.current_a,
            "charge_drawn_mah": truth.charge_drawn_c / MAH_TO_COULOMB,
            "failure": FAILURES[self.failure],
            "SIM_BAT_ENABLE": int(self.enabled),
            "SIM_BAT_DRAIN": self.drain_s,
            "SIM_BAT_MIN_PCT": 100.0 * self.drain_min,
        }

    # -- what the autopilot's channel calls ------------------------------------------------------
    def inject_failure(self, failure_type: int) -> bool:
        """MAV_CMD_INJECT_FAILURE for the battery: ``failure_type`` a MAVLink FAILURE_TYPE
        (see the module's docstring); False for the types a battery monitor has no meaning for
        (the failure in force is kept then). Takes effect at the next report."""
        if failure_type not in FAILURES:
            return False
        if failure_type == FAILURE_STUCK and self.failure != FAILURE_STUCK:
            self._stuck = self.reading
        self.failure = failure_type
        self.reading = self._measured()
        return True

    def set_parameter(self, name: str, value: float) -> bool:
        """``SIM_BAT_ENABLE`` (0/1), ``SIM_BAT_DRAIN`` (s, 0: the pack model) or ``SIM_BAT_MIN_PCT``
        (%), as PX4's parameters; False for another name or a value out of PX4's range (or not a
        finite number), the model unchanged."""
        spec = SIM_BATTERY_PARAMETERS.get(name)
        if spec is None or isinstance(value, bool) or not isinstance(value, int | float):
            return False
        value = float(value)
        if not (math.isfinite(value) and spec[0] <= value <= spec[1]):
            return False
        if name == SIM_BAT_ENABLE:
            if value not in (0.0, 1.0):
                return False
            self.enabled = value == 1.0
        elif name == SIM_BAT_DRAIN:  # (a switch between the two ways keeps the state of charge)
            self.drain_s = value
        else:
            self.drain_min = value / 100.0
        return True
