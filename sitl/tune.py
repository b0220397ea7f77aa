"""``quadsitl tune``: PX4's multicopter attitude autotune flown on the whole stack in-process, and
the controller file it gives (``config/controllers/px4_pid_tuned.toml``).

What a PX4 user does with ``mc_autotune_attitude_control``, in simulation time: the vehicle takes
off on its current gains (``px4_pid``: PX4's defaults) and hovers at 2.5 m (the ``hover``
scenario); then roll, pitch and yaw in turn get PX4's identification signal added to their rate
setpoint (the ``px4_attitude`` law's autotune input), each is identified from the rate
controller's torque (the cascade's, read from the autopilot's controller rows) to the body rate
while the closed loop flies, a PID and an attitude gain are designed from the model, with 2 s of
rest between axes; the gains are kept if PX4's check accepts them. :mod:`autopilot.control.autotune`
has the maths. The position and velocity gains (MPC_*) are not the autotune's: they are kept
(PX4's defaults, in acceleration units: the same on any vehicle whose hover thrust is known).

Where this differs from PX4's module, and why:

* **The model's order follows the actuation** (:func:`model_order`). PX4 fits a second-order
  model, right for rotors (their lag, then the inertia: ``--vehicle paper_quad_rotors`` identifies
  the 20 ms rotor pole). Under wrench actuation (the paper's vehicle) the torque is applied as
  commanded and the rate dynamics are first order, ``tau_max / (J s)``; a second-order fit leaves
  one direction of its coefficients unexcited, its variance stays in the thousands, and PX4's
  convergence test fails the axis after 20 s (``--order 2`` shows it). The first-order model is
  the special case ``a2 = b1 = b2 = 0`` of PX4's, and PX4's gain design applies to it unchanged.
* **The gyro is not filtered** here (the controllers get the estimate as it is), so the model is
  sampled at the control period (2 ms at 500 Hz): PX4's rule ``max(1 / (2 IMU_GYRO_CUTOFF),
  sample period)`` with no cutoff. ``--gyro-cutoff 40`` (PX4's default) gives a 10 ms model, into
  which the unfiltered loop's fast torque aliases (its gain comes out 7-10 % low).
* **Yaw's rise time is an option** (``--yaw-rise-time``); PX4 fixes it at 0.2 s.
* A tuned gain outside its parameter's declared range is brought into it, and said so (PX4 saves
  what it computed).
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from pathlib import Path

from autopilot.control import autotune as at
from autopilot.control.config import ControllerConfig, load_controller
from autopilot.control.laws import px4_attitude
from quadcommon.bus_records import CONTROLLER_FIELDS, TRUTH_FIELDS
from quadcommon.cli_help import HelpFormatter
from quadcommon.config import VehicleConfig, load_scenario, load_vehicle
from quadcommon.rigid_body import body_torque_from_euler_torque

from .inprocess import Lockstep, RunOptions, paper_stack

AXES = ("roll", "pitch", "yaw")
HOVER_S = 10.0  # on the default gains, the hover has settled (takeoff to 2.5 m) by then
TUNED_NAME = "px4_pid_tuned"
_RATE, _PHI = TRUTH_FIELDS.index("p_rad_s"), TRUTH_FIELDS.index("phi_rad")
_TAU = CONTROLLER_FIELDS.index("tau_phi_n_m")
# the gains of each axis in the rotational section: rate P, I, D, K and the attitude P
_KEYS = {
    "roll": ("mc_rollrate_p", "mc_rollrate_i", "mc_rollrate_d", "mc_rollrate_k", "mc_roll_p"),
    "pitch": ("mc_pitchrate_p", "mc_pitchrate_i", "mc_pitchrate_d", "mc_pitchrate_k", "mc_pitch_p"),
    "yaw": ("mc_yawrate_p", "mc_yawrate_i", "mc_yawrate_d", "mc_yawrate_k", "mc_yaw_p"),
}


@dataclass(frozen=True)
class TuneOptions:
    """The autotune's settings, PX4's parameter in brackets."""

    rise_time_s: float = at.RISE_TIME_S  # roll and pitch (MC_AT_RISE_TIME)
    yaw_rise_time_s: float = at.YAW_RISE_TIME_S  # fixed in PX4
    amplitude_rad_s: float = at.EXCITATION_AMPLITUDE_RAD_S  # (MC_AT_SYSID_AMP)
    gyro_cutoff_hz: float | None = None  # (IMU_GYRO_CUTOFF) None: the gyro is not filtered
    nominal_plant: bool = False  # identify the Section II model instead of the coupled plant
    order: int | None = None  # the ARX model's order; None: the vehicle's (model_order)


@dataclass(frozen=True)
class AxisResult:
    axis: str
    model: at.AxisModel
    gains: at.AxisGains


@dataclass(frozen=True)
class TuneResult:
    base: ControllerConfig  # the gains the vehicle flew during the autotune
    tuned: ControllerConfig  # the base with the tuned rate and attitude gains
    axes: tuple[AxisResult, ...]
    accepted: bool  # PX4's check (gains_are_good) passed
    vehicle: str
    options: TuneOptions
    limited: tuple[str, ...] = ()  # gains brought into their parameter's range, said how


class AutotuneFailed(RuntimeError):
    """An axis was not identified within PX4's 20 s."""


RISE_TIME_STEP_S = 0.01  # MC_AT_RISE_TIME's resolution (two decimals) and minimum


def fastest_rise_time(model: at.AxisModel, longest_s: float = 0.5) -> float | None:
    """The shortest rise time, in PX4's 0.01 s steps up to ``longest_s``, whose gains for ``model``
    pass PX4's check (:func:`~autopilot.control.autotune.gains_are_good`); None if none does."""
    for k in range(1, int(round(longest_s / RISE_TIME_STEP_S)) + 1):
        rise_time = round(k * RISE_TIME_STEP_S, 2)
        if at.gains_are_good((at.axis_gains(model, rise_time),)):
            return rise_time
    return None


def model_order(vehicle: VehicleConfig) -> int:
    """The order of the rate dynamics from the rate controller's torque to the body rate: 2 (PX4's
    model: the rotors' lag, then the inertia) with rotors, 1 under wrench actuation, where the
    torque is applied as commanded and the body rate integrates it (``tau_max / (J s)``). A second-
    order model of a first-order plant leaves one direction of its coefficients unexcited: its
    variance stays in the thousands and PX4's convergence test never holds."""
    return 2 if vehicle.actuation.mode == "rotors" else 1


def identify_axis(stack: Lockstep, axis: int, options: TuneOptions) -> at.AxisModel:
    """Excite and identify body axis ``axis`` (0 roll, 1 pitch, 2 yaw) until PX4's convergence
    test holds (AutotuneFailed after 20 s); the excitation is off again on return."""
    cascade = stack.autopilot.cascade
    rotational = cascade.config.rotational
    keys = _KEYS[AXES[axis]]
    scale = 1.0 / (getattr(rotational, keys[0]) * getattr(rotational, keys[3]))
    identification = at.AxisIdentification(cascade.dt, options.gyro_cutoff_hz, scale,
                                           options.order or model_order(cascade.vehicle))  # fmt: skip
    excitation = at.Excitation(options.amplitude_rad_s)
    torque_max = cascade.context.torque_max_n_m[axis]
    slot = px4_attitude.GAINS.autotune_rate + axis
    start, next_update = stack.t, stack.t
    try:
        while True:
            elapsed = stack.t - start
            if stack.t >= next_update - 1e-9:  # PX4's publishing loop: the state machine, the signal
                if elapsed > at.MIN_AXIS_TIME_S and identification.converged():
                    return identification.model(elapsed)
                if elapsed > at.AXIS_TIMEOUT_S:
                    raise AutotuneFailed(f"{AXES[axis]} not identified in {at.AXIS_TIMEOUT_S:g} s: variances "
                                         f"{identification.rls.variances.round(1).tolist()}")  # fmt: skip
                # the signal starts once the filters hold a sample (of the hover, as in PX4)
                cascade.gr[slot] = excitation.advance() if identification.started else 0.0
                next_update += at.EXCITATION_PERIOD_S
            stack.step()
            # this frame's torque, as the cascade gave it (PX4's torque setpoint; the controller row
            # has it on the Euler coordinates), and the body rate it was computed from
            truth, controller = stack.truth_rows[-1], stack.controller_rows[-1]
            torque = body_torque_from_euler_torque(truth[_PHI], truth[_PHI + 1], controller[_TAU:_TAU + 3])
            identification.update(torque[axis] / torque_max, truth[_RATE + axis])
    finally:
        cascade.gr[slot] = 0.0


def autotune(
    vehicle: str = "paper_quad",
    controller: str = "px4_pid",
    options: TuneOptions = TuneOptions(),
    log: Callable[[str], None] = lambda text: None,
) -> TuneResult:
    """PX4's autotune of ``controller`` (a cascade with the ``px4_attitude`` law) on ``vehicle``,
    flown in-process from a takeoff to a hover at 2.5 m (the ``hover`` scenario)."""
    base = load_controller(controller)
    if base.rotational.law != px4_attitude.Px4Attitude.NAME:
        raise ValueError(f"{controller}: the autotune tunes the px4_attitude law, not {base.rotational.law}")
    scenario = replace(load_scenario("hover"), vehicle=vehicle)
    stack = paper_stack(scenario, base, RunOptions(nominal_plant=options.nominal_plant),
                        vehicle=load_vehicle(vehicle))  # fmt: skip
    stack.run_for(HOVER_S)
    results = []
    for axis, name in enumerate(AXES):
        model = identify_axis(stack, axis, options)
        rise_time = options.yaw_rise_time_s if name == "yaw" else options.rise_time_s
        gains = at.axis_gains(model, rise_time)
        log(f"{name}: identified in {model.duration_s:.1f} s; MC_{name.upper()}RATE_P/I/D = "
            f"{gains.parallel[0]:.4g} / {gains.parallel[1]:.4g} / {gains.parallel[2]:.4g}, "
            f"MC_{name.upper()}_P = {gains.attitude_p:.4g}")  # fmt: skip
        results.append(AxisResult(name, model, gains))
        stack.run_for(at.PAUSE_S)  # PX4 lets the vehicle settle before the next axis
    accepted = at.gains_are_good(tuple(r.gains for r in results))
    changes, limited = {}, []
    ranges = {row.key: (row.lo, row.hi) for row in px4_attitude.TUNABLE_GAINS}
    for r in results:
        p, i, d, k, attitude = _KEYS[r.axis]
        values = {p: r.gains.parallel[0], i: r.gains.parallel[1], d: r.gains.parallel[2], k: 1.0,
                  attitude: r.gains.attitude_p}  # fmt: skip
        for key, value in values.items():  # PX4 saves what it computed; here a parameter keeps its range
            lo, hi = ranges[key]
            changes[key] = min(max(value, lo), hi)
            if changes[key] != value:
                limited.append(f"{key.upper()} {value:.4g} -> {changes[key]:g} (its range [{lo:g}, {hi:g}])")
                log(f"{key.upper()} = {value:.4g} is outside the parameter's range: {changes[key]:g}")
    tuned = replace(base, name=TUNED_NAME, rotational=replace(base.rotational, **changes))
    return TuneResult(base, tuned, tuple(results), accepted, vehicle, options, tuple(limited))


def nominal_rate_gain(vehicle: str, axis: int) -> float:
    """The body rate's acceleration per unit normalised torque on the nominal vehicle,
    ``tau_max / J`` (rad/s^2): the identified model's integrator gain, ideally."""
    v = load_vehicle(vehicle)
    return v.actuation.torque_max_n_m[axis] / v.nominal.inertia_kg_m2[axis]


def model_gain_ratio(result: AxisResult, vehicle: str, frequency_hz: float) -> float:
    """|identified response| / |tau_max / (J j omega)| at ``frequency_hz``: 1 for a model that is
    the nominal integrator there."""
    nominal = nominal_rate_gain(vehicle, AXES.index(result.axis)) / (2.0 * math.pi * frequency_hz)
    return abs(result.model.frequency_response(frequency_hz)) / nominal


# -- the controller file ----------------------------------------------------------------------------
def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return f"{float(f'{v:.4g}')!r}"  # 4 significant digits, as a TOML float
    return repr(v) if not isinstance(v, str) else f'"{v}"'


def controller_toml(result: TuneResult, command: str) -> str:
    """The tuned controller as a controller file, its header saying how it was made."""
    o = result.options
    cutoff = "none (the gyro is not filtered)" if o.gyro_cutoff_hz is None else f"{o.gyro_cutoff_hz:g} Hz"
    first = result.axes[0].model
    order = "first" if first.a[1] == 0.0 and first.b[1:] == (0.0, 0.0) else "second"
    lines = [
        "# PX4's multicopter cascade (as px4_pid) with rate and attitude gains from PX4's autotune",
        "# (mc_autotune_attitude_control's method) flown on this vehicle. Generated by:",
        f"#   {command}",
        "# (sitl/tune.py; docs/controllers.md). Do not edit the tuned gains by hand: run it again.",
        f"# Vehicle {result.vehicle}; base {result.base.name} (the gains flown while identifying);",
        f"# MC_AT_RISE_TIME {o.rise_time_s:g} s (roll, pitch), {o.yaw_rise_time_s:g} s (yaw); "
        f"MC_AT_SYSID_AMP {o.amplitude_rad_s:g} rad/s;",
        f"# IMU_GYRO_CUTOFF {cutoff}. Identified: a {order}-order ARX model,",
        f"# normalised torque -> body rate, dt {first.dt_s * 1e3:g} ms:",
    ]
    for r in result.axes:
        m = r.model
        lines.append(f"#   {r.axis:<5}: a = ({m.a[0]:.5f}, {m.a[1]:.5f}), b = ({m.b[0]:.5f}, {m.b[1]:.5f}, "
                     f"{m.b[2]:.5f}) in {m.duration_s:.1f} s")  # fmt: skip
    lines += [f"# Brought into its parameter's range: {text}" for text in result.limited]
    lines += [
        "# MPC_* (position, velocity) are PX4's defaults: the autotune does not tune them, and in",
        "# acceleration units they do not depend on the vehicle. Integrator limits 1.0 (px4_pid.toml).",
        f'name = "{result.tuned.name}"',
        'description = "PX4 cascade with gains from PX4\'s autotune on this vehicle"',
    ]
    tuned = result.tuned
    for section, gains in (("translational", tuned.translational), ("rotational", tuned.rotational)):
        lines += ["", f"[{section}]"]
        lines += [f"{f.name} = {_value(getattr(gains, f.name))}" for f in fields(gains)]
        if section == "translational":
            lines.append(f"tilt_max_rad = {tuned.tilt_max_rad!r}")
    cf = tuned.command_filter
    lines += ["", "[command_filter]", f"enabled = {_value(cf.enabled)}"]
    if cf.enabled:
        lines += [f"natural_frequency_rad_s = {cf.natural_frequency_rad_s!r}", f"damping = {cf.damping!r}"]
    return "\n".join(lines) + "\n"


def parse_arguments(argv: list[str]) -> argparse.Namespace:
    """``quadsitl tune``'s arguments (``options`` among them: the TuneOptions they ask for)."""
    parser = argparse.ArgumentParser(
        prog="quadsitl tune",
        formatter_class=HelpFormatter,
        description="PX4's multicopter attitude autotune flown in-process: identify roll, pitch and yaw "
        "while hovering on a px4_attitude cascade, print the gains and write the tuned controller file.",
    )
    parser.add_argument("--vehicle", default="paper_quad", help="vehicle (config/vehicle)")
    parser.add_argument("--controller", default="px4_pid", help="the cascade flown while identifying")
    parser.add_argument("--rise-time", type=float, default=at.RISE_TIME_S,
                        help="MC_AT_RISE_TIME (s): the rate loop's wanted rise time, roll and pitch")
    parser.add_argument("--yaw-rise-time", type=float, default=at.YAW_RISE_TIME_S,
                        help="the yaw rate loop's wanted rise time (s; fixed in PX4)")
    parser.add_argument("--amplitude", type=float, default=at.EXCITATION_AMPLITUDE_RAD_S,
                        help="MC_AT_SYSID_AMP (rad/s)")
    parser.add_argument("--gyro-cutoff", type=float, default=None,
                        help="IMU_GYRO_CUTOFF (Hz) of the identification's filters (default: none, as this "
                        "stack's gyro)")
    parser.add_argument("--nominal-plant", action="store_true", help="identify the Section II model")
    parser.add_argument("--order", type=int, default=None, choices=(1, 2),
                        help="the ARX model's order (default: 1 under wrench actuation, 2 with rotors)")
    parser.add_argument("--out", default=None, help="write the controller file here")
    args = parser.parse_args(argv)  # fmt: skip
    args.options = TuneOptions(args.rise_time, args.yaw_rise_time, args.amplitude, args.gyro_cutoff,
                               args.nominal_plant, args.order)  # fmt: skip
    return args


def main(argv: list[str] | None = None) -> int:
    """``quadsitl tune``: fly PX4's attitude autotune in-process (see the module docstring); print (or
    write to ``--out``) the controller TOML; 1 when the identification does not converge or PX4's checks
    refuse the gains."""
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse_arguments(argv)
    try:
        result = autotune(args.vehicle, args.controller, args.options, log=print)
    except AutotuneFailed as exc:
        print(f"quadsitl tune: {exc} (PX4's convergence test: every variance below "
              f"{at.CONVERGED_VARIANCE:g}); nothing written", file=sys.stderr)  # fmt: skip
        return 1
    for r in result.axes:
        ratios = ", ".join(f"{model_gain_ratio(r, args.vehicle, f):.3f}" for f in (1.0, 3.0, 10.0))
        fastest = fastest_rise_time(r.model)
        print(f"{r.axis}: |model| / (tau_max / J omega) at 1, 3, 10 Hz: {ratios}; PX4's check accepts rise "
              f"times from {fastest if fastest is not None else 'none'} s")  # fmt: skip
    if not result.accepted:
        print("quadsitl tune: PX4's check refuses these gains (kc in (0, 0.5), ki in (0, 10), "
              "kd in [0, 0.1), attitude P in (0, 12)); nothing written", file=sys.stderr)  # fmt: skip
        return 1
    text = controller_toml(result, " ".join(["quadsitl tune", *argv]))
    if args.out:
        Path(args.out).write_text(text)
        print(f"wrote {args.out}")
    else:
        print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
