"""The remaining charge of the flight battery, estimated as PX4's battery library estimates it.

Pure: each report of the battery monitor (``BATTERY_STATUS`` in the lockstep frame, the pack's
voltage and current, :mod:`autopilot.mavlink.hil`) comes in with its simulation time; out comes a
:class:`BatteryStatus` with PX4's ``battery_status`` fields, the one estimate that SYS_STATUS,
BATTERY_STATUS, the flight log and the commander's failsafes all read. The steps are those of
PX4's ``src/lib/battery/battery.cpp`` (parameters by PX4's names):

* **connected**: a voltage of at least 2.1 V (a lithium cell's); the estimate starts 2 s after
  the pack connected (the filters are reset to each sample until then: no reliance on the
  rising edge);
* **coulomb counting**: ``discharged_mah += I dt / 3.6`` for every measured current;
* **voltage-based estimate**: the cell voltage ``V / BAT1_N_CELLS`` corrected for the load by the
  internal resistance, ``+ R I`` (``R`` = ``BAT1_R_INTERNAL`` per cell, or when that is negative
  PX4's online estimate: a recursive least-squares fit of ``V = OCV - R_pack I`` with a forgetting
  factor of 0.95, updated only when it improves its covariance), through a 1 s filter, then linear
  between ``BAT1_V_EMPTY`` (0) and ``BAT1_V_CHARGED`` (1);
* **fusion** when ``BAT1_CAPACITY`` is known: each report pulls the charge towards the
  voltage-based one by ``0.03 (1 - soc_v)`` (harder the emptier the pack reads), takes off the
  report's counted charge, and never reads above the coulomb count's ``1 - discharged / capacity``;
  without a capacity, the voltage-based estimate alone;
* **warning**: below ``BAT_EMERGEN_THR`` emergency, ``BAT_CRIT_THR`` critical, ``BAT_LOW_THR`` low
  (strict comparisons, only once the estimate started);
* **time remaining**: the remaining charge over the average current (a 50 s filter of the
  measured current while armed, started at ``BAT_AVRG_CURRENT``), when the capacity is known;
* **faults**: a voltage above ``1.05 BAT1_N_CELLS BAT1_V_CHARGED`` (PX4 reports over-voltage as
  ``FAULT_SPIKES``, MAVLink's ``MAV_BATTERY_FAULT_SPIKES``).

Where this differs from PX4: the filters take each report's own interval (PX4's take the driver's
nominal one); a current that is not measured (PX4's -1) neither resets the filters with -1 A nor
feeds the average current. ``BAT1_N_CELLS`` = 0 (not configured) leaves the charge unknown (-1)
and raises no warning. ``voltage_filtered_v`` and ``current_filtered_a`` (the fields Flight Review
plots, from PX4's older battery library) are the measured values through a 1 s filter.

A pack whose reports stop for 5 s is unhealthy (:meth:`BatteryEstimator.unhealthy`, PX4's
batteryCheck); one that never reported is no battery at all.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from ..params.store import ParameterStore

# PX4's battery_status.warning
WARNING_NONE, WARNING_LOW, WARNING_CRITICAL, WARNING_EMERGENCY = 0, 1, 2, 3
# PX4's battery_status fault bits (bit index; MAVLink's MAV_BATTERY_FAULT is 1 << index)
FAULT_SPIKES = 1
FAULT_NAMES = {FAULT_SPIKES: "over voltage"}  # PX4's batteryCheck words
RECOGNITION_V = 2.1  # LITHIUM_BATTERY_RECOGNITION_VOLTAGE
SETTLE_S = 2.0  # connected this long before the estimate starts
UNHEALTHY_AFTER_S = 5.0  # no report for this long: the pack is unhealthy
OVER_VOLTAGE = 1.05  # of the charged voltage: a fault
CURRENT_UNKNOWN = -1.0  # PX4's current_a when nothing measures it
# PX4's internal-resistance estimator (battery.h)
RLS_FORGETTING = 0.95
R_DEFAULT_OHM = 0.005  # per cell
OCV_DEFAULT_V = 4.2  # per cell
R_COVARIANCE = 0.1  # per cell
OCV_COVARIANCE = 1.5  # per cell
CELL_FILTER_S = 1.0
OCV_FILTER_S = 1.0
AVERAGE_CURRENT_FILTER_S = 50.0
MEASURED_FILTER_S = 1.0  # voltage_filtered_v, current_filtered_a
VOLTAGE_WEIGHT = 3e-2  # the fusion's pull towards the voltage-based estimate, per report
MAX_DT_S = 2.0
EPSILON = 1.1920929e-07  # FLT_EPSILON


class BatteryStatus(NamedTuple):
    """One estimate (PX4's ``battery_status``): what SYS_STATUS, BATTERY_STATUS, the flight log
    and the failsafes read."""

    time_s: float  # the report's simulation time
    connected: bool
    voltage_v: float  # measured
    voltage_filtered_v: float
    current_a: float  # measured; -1: not measured
    current_filtered_a: float
    current_average_a: float  # the time remaining's average (50 s)
    discharged_mah: float  # coulomb count
    remaining: float  # 0-1; -1: unknown
    scale: float  # PX4's thrust scale for a sagging pack, [1, 1.3]
    time_remaining_s: float  # NaN: unknown (no capacity)
    cell_count: int
    capacity_mah: float  # -1: unknown
    warning: int  # WARNING_*
    faults: int  # bits 1 << FAULT_*
    internal_resistance_estimate: float  # per cell, ohm
    ocv_estimate: float  # V, the pack's
    ocv_estimate_filtered: float
    volt_based_soc_estimate: float  # 0-1; -1: unknown


class _AlphaFilter:
    """A first-order low-pass filter (PX4's AlphaFilter): ``x += dt / (tau + dt) (sample - x)``."""

    __slots__ = ("time_constant_s", "state")

    def __init__(self, time_constant_s: float, state: float = 0.0) -> None:
        self.time_constant_s = time_constant_s
        self.state = state

    def update(self, sample: float, dt: float) -> float:
        self.state += dt / (self.time_constant_s + dt) * (sample - self.state)
        return self.state


def _interpolate(x: float, x0: float, x1: float, y0: float, y1: float) -> float:
    """PX4's math::interpolate: linear, clamped to [y0, y1]."""
    if x <= x0:
        return y0
    if x >= x1:
        return y1
    return y0 + (x - x0) * (y1 - y0) / (x1 - x0)


class BatteryEstimator:
    """The battery library for one pack; :meth:`update` at each monitor report."""

    def __init__(self, params: ParameterStore) -> None:
        self.params = params
        self.reset()

    def reset(self) -> None:
        """Forget the pack (a restarted simulator)."""
        self.status: BatteryStatus | None = None  # None: no report yet (no battery)
        self.last_report_s: float | None = None
        self._last_unconnected_s: float | None = None
        self._discharged_mah = 0.0
        self._state_of_charge = -1.0
        self._warning = WARNING_NONE
        self._cells = -1  # the BAT1_N_CELLS the RLS was set up for
        self._theta = [0.0, 0.0]  # RLS: [open-circuit voltage (V), internal resistance (ohm)] of the pack
        self._covariance = [[0.0, 0.0], [0.0, 0.0]]
        self._covariance_norm = 0.0
        self._r_estimate = R_DEFAULT_OHM  # per cell
        self._cell_filter = _AlphaFilter(CELL_FILTER_S)
        self._ocv_filter = _AlphaFilter(OCV_FILTER_S)
        self._average_current = _AlphaFilter(AVERAGE_CURRENT_FILTER_S, math.nan)
        self._voltage_filter = _AlphaFilter(MEASURED_FILTER_S)
        self._current_filter = _AlphaFilter(MEASURED_FILTER_S)

    def unhealthy(self, t_s: float) -> bool:
        """A pack that reported once and not for :data:`UNHEALTHY_AFTER_S` (simulation time)."""
        last = self.last_report_s
        return last is not None and t_s - last > UNHEALTHY_AFTER_S

    def update(self, t_s: float, voltage_v: float, current_a: float, armed: bool) -> BatteryStatus:
        """One report at ``t_s`` (s): the pack's voltage (V) and current (A; NaN: not measured);
        ``armed``: the time remaining averages the current only in flight."""
        p = self.params.values
        cells = int(p["BAT1_N_CELLS"])
        v_empty, v_charged = p["BAT1_V_EMPTY"], p["BAT1_V_CHARGED"]
        capacity = p["BAT1_CAPACITY"]
        r_param = p["BAT1_R_INTERNAL"]
        if cells != self._cells:
            self._init_resistance_estimate(cells)
        dt_discharge = t_s - self.last_report_s if self.last_report_s is not None else 0.0
        dt = min(max(dt_discharge, 0.0), MAX_DT_S)
        self.last_report_s = t_s
        current = current_a if current_a == current_a else CURRENT_UNKNOWN
        measured = current != CURRENT_UNKNOWN

        connected = voltage_v >= RECOGNITION_V
        if not connected or self._last_unconnected_s is None:
            self._last_unconnected_s = t_s
        initialized = connected and t_s > self._last_unconnected_s + SETTLE_S
        if connected and not initialized and cells > 0:
            self._reset_resistance_estimate(voltage_v, max(current, 0.0), cells, r_param)
            self._voltage_filter.state = voltage_v
            self._current_filter.state = current
        else:
            self._voltage_filter.update(voltage_v, dt)
            self._current_filter.update(current, dt)

        counted_mah = 0.0
        if dt_discharge > EPSILON and measured:
            counted_mah = current * 1e3 * dt_discharge / 3600.0
            self._discharged_mah += counted_mah
        soc_v = self._voltage_based(voltage_v, current, cells, v_empty, v_charged, r_param, dt)

        if capacity > 0.0 and initialized:
            weight = VOLTAGE_WEIGHT * (1.0 - soc_v)
            soc = (1.0 - weight) * self._state_of_charge + weight * soc_v
            soc = max(soc - counted_mah / capacity, 0.0)
            self._state_of_charge = min(max(1.0 - self._discharged_mah / capacity, 0.0), soc)
        else:
            self._state_of_charge = soc_v
        soc = self._state_of_charge

        scale = v_charged / self._cell_filter.state if self._cell_filter.state > 0.0 else 1.0
        scale = min(max(scale, 1.0), 1.3) if math.isfinite(scale) else 1.0
        if connected and initialized:
            self._warning = self._determine_warning(soc, cells)
        faults = (1 << FAULT_SPIKES) if cells > 0 and voltage_v > cells * v_charged * OVER_VOLTAGE else 0

        average = self._average_current
        if not math.isfinite(average.state) or average.state < EPSILON:
            average.state = p["BAT_AVRG_CURRENT"]
        if armed and measured:
            average.update(max(current, 0.0), dt)
        remaining_s = math.nan
        if capacity > 0.0:
            remaining_s = soc * capacity / max(average.state * 1e3, EPSILON) * 3600.0

        ocv = voltage_v + self._r_estimate * cells * current
        ocv_soc = -1.0
        if cells > 0:
            ocv_soc = _interpolate(self._ocv_filter.state / cells, v_empty, v_charged, 0.0, 1.0)
        self.status = BatteryStatus(
            t_s, connected, voltage_v, self._voltage_filter.state, current, self._current_filter.state,
            average.state, self._discharged_mah, soc, scale, remaining_s, cells, capacity, self._warning,
            faults, self._r_estimate, ocv, self._ocv_filter.state, ocv_soc,
        )  # fmt: skip
        return self.status

    def _determine_warning(self, soc: float, cells: int) -> int:
        if cells <= 0 or soc < 0.0:  # not configured: the charge is unknown
            return WARNING_NONE
        p = self.params.values
        if soc < p["BAT_EMERGEN_THR"]:
            return WARNING_EMERGENCY
        if soc < p["BAT_CRIT_THR"]:
            return WARNING_CRITICAL
        if soc < p["BAT_LOW_THR"]:
            return WARNING_LOW
        return WARNING_NONE

    def _voltage_based(self, voltage, current, cells, v_empty, v_charged, r_param, dt) -> float:
        """The charge from the load-compensated cell voltage (0-1; -1 without a cell count)."""
        if cells <= 0:
            return -1.0
        cell_v = voltage / cells
        if current > EPSILON:
            self._update_resistance_estimate(voltage, current, cells, dt)
            cell_v += (r_param if r_param >= 0.0 else self._r_estimate) * current
        self._cell_filter.update(cell_v, dt)
        return _interpolate(self._cell_filter.state, v_empty, v_charged, 0.0, 1.0)

    # -- PX4's internal-resistance estimate (recursive least squares) ---------------------------
    def _init_resistance_estimate(self, cells: int) -> None:
        self._cells = cells
        self._theta = [OCV_DEFAULT_V * cells, R_DEFAULT_OHM * cells]
        self._covariance = [[OCV_COVARIANCE * cells, 0.0], [0.0, R_COVARIANCE * cells]]
        self._covariance_norm = _norm(self._covariance)

    def _reset_resistance_estimate(self, voltage: float, current: float, cells: int, r_param: float) -> None:
        self._init_resistance_estimate(cells)
        self._theta[0] = voltage
        self._r_estimate = R_DEFAULT_OHM
        self._ocv_filter.state = voltage + self._r_estimate * cells * current
        r = r_param if r_param >= 0.0 else self._r_estimate
        self._cell_filter.state = voltage / cells + r * current

    def _update_resistance_estimate(self, voltage: float, current: float, cells: int, dt: float) -> None:
        """One step of the fit ``V = OCV - R_pack I`` (x = [1, -I]); kept only if it shrinks the
        covariance's norm, else only the OCV follows the measurement."""
        (p00, p01), (p10, p11) = self._covariance
        theta = self._theta
        predicted = theta[0] - current * theta[1]
        error = voltage - predicted
        px0, px1 = p00 - current * p01, p10 - current * p11  # P x
        denominator = RLS_FORGETTING + px0 - current * px1  # lambda + x' P x
        g0, g1 = px0 / denominator, px1 / denominator
        xp0, xp1 = p00 - current * p10, p01 - current * p11  # x' P
        lam = RLS_FORGETTING
        covariance = [[(p00 - g0 * xp0) / lam, (p01 - g0 * xp1) / lam],
                      [(p10 - g1 * xp0) / lam, (p11 - g1 * xp1) / lam]]  # fmt: skip
        norm = _norm(covariance)
        if norm < self._covariance_norm:
            self._theta = [theta[0] + g0 * error, theta[1] + g1 * error]
            self._covariance = covariance
            self._covariance_norm = norm
            self._r_estimate = max(self._theta[1] / cells, 0.0)
        else:
            theta[0] = voltage + theta[1] * current
        self._ocv_filter.update(voltage + self._r_estimate * cells * current, dt)


def _norm(m: list[list[float]]) -> float:
    return math.sqrt(m[0][0] ** 2 + 2.0 * m[1][0] ** 2 + m[1][1] ** 2)
