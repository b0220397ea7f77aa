"""PX4's multicopter attitude autotune (``mc_autotune_attitude_control``) as maths: the excitation,
the identification of each axis and the gain design. Pure: samples and times come in as arguments;
:mod:`sitl.tune` flies the vehicle and feeds them.

PX4's method, per body axis (roll, then pitch, then yaw), with the vehicle hovering on its current
gains:

1. **Excitation** (:class:`Excitation`): a rate setpoint added to the attitude controller's output
   (mc_att_control adds ``autotune_attitude_control_status.rate_sp``): a step between 0 and
   MC_AT_SYSID_AMP (0.7 rad/s), its half-periods 0.6 s (short, to keep the vehicle centred), then
   1.0, 0.9, ... 0.2 s, then 0.6, 0.5, ... 0.2 s over and over, washed out:
   ``signal = step - lowpass(step)``, the low pass a first-order filter of time constant 0.2 s
   stepped with the signal every 0.1 s.
2. **Identification** (:class:`AxisIdentification`): the input ``u`` is the rate controller's
   normalised torque on that axis (scaled by ``1 / (MC_*RATE_P MC_*RATE_K)`` so that ``u`` and
   ``y`` have similar ranges, and scaled back afterwards), the output ``y`` the body rate (rad/s).
   Both pass the same filters: a second-order Butterworth low pass at the gyro's cutoff
   (IMU_GYRO_CUTOFF; none where the gyro is not filtered) and a first-order high pass at 0.5 Hz
   (removes the offsets: the torque that holds the hover, a slow drift). A second-order ARX model
   with one sample of delay (:class:`ArxRls`),
   ``y(k) = -a1 y(k-1) - a2 y(k-2) + b0 u(k-1) + b1 u(k-2) + b2 u(k-3)`` (or its first-order
   special case ``y(k) = -a1 y(k-1) + b0 u(k-1)``, for a plant without actuator lag:
   :mod:`sitl.tune`), is fitted by recursive least squares with a forgetting factor
   ``1 - dt / 60 s``, sampled every ``max(1 / (2 IMU_GYRO_CUTOFF), sample period)`` within
   [2, 10] ms (the gyro's cutoff bounds the loop's bandwidth). An axis is identified when every
   coefficient's variance (the diagonal of the RLS covariance) is below 50 and at least 5 s have
   passed; 20 s without that is a failure.
3. **Gains** (:func:`gmvc_pid`, :func:`attitude_gain`): a PID by generalised minimum variance
   control (Yamamoto, Fujii & Kaneda, "Design and implementation of a self-tuning PID
   controller", 1998) from the identified model, the closed loop asked to behave as a critically
   damped second-order system of rise time MC_AT_RISE_TIME (roll, pitch; 0.14 s by default) or
   0.2 s (yaw), detuned by 0.7 (see :func:`gmvc_pid`); then the attitude P gain from PX4's
   empirical rule, "an error of 60 degrees gives the largest output": ``K_att K_rate rad(60) = 1``,
   within [2, 6.5]. The gains are saved in PX4's parallel form (MC_*RATE_P = kc, _I = kc ki,
   _D = kc kd, _K = 1) once :func:`gains_are_good` accepts all three axes.

Written from PX4's ``mc_autotune_attitude_control.cpp``, ``lib/system_identification`` and
``lib/pid_design`` (the method, not the code).
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass

import numpy as np

EXCITATION_AMPLITUDE_RAD_S = 0.7  # MC_AT_SYSID_AMP's default
EXCITATION_PERIOD_S = 0.1  # the module's publishing loop: the signal changes this often
EXCITATION_WASHOUT_S = 0.2  # time constant of the low pass the step is washed out with
HIGH_PASS_HZ = 0.5  # the identification's high pass, on input and output
MODEL_DT_MIN_S, MODEL_DT_MAX_S = 2e-3, 10e-3
FORGETTING_TIME_S = 60.0  # RLS forgetting factor 1 - model_dt / 60 s
INITIAL_VARIANCE = 10e3  # the RLS covariance's diagonal at reset
CONVERGED_VARIANCE = 50.0  # every coefficient's variance below this: the axis is identified
MIN_AXIS_TIME_S, AXIS_TIMEOUT_S, PAUSE_S = 5.0, 20.0, 2.0
RISE_TIME_S = 0.14  # MC_AT_RISE_TIME's default (roll and pitch)
YAW_RISE_TIME_S = 0.2  # fixed in PX4 for yaw
DETUNING = 0.7  # the GMVC's lambda, as PX4 designs with
DAMPING_INDEX = 0.0  # 0: critical damping (1: Butterworth)
ATTITUDE_P_RANGE = (2.0, 6.5)
FULL_OUTPUT_ERROR_RAD = math.radians(60.0)  # the attitude error that should give the largest output


class Excitation:
    """PX4's identification signal (module docstring, step 1): call :meth:`advance` every
    :data:`EXCITATION_PERIOD_S`; it returns the rate setpoint (rad/s) to add until the next call."""

    def __init__(self, amplitude_rad_s: float = EXCITATION_AMPLITUDE_RAD_S) -> None:
        self.amplitude = amplitude_rad_s
        self.alpha = EXCITATION_PERIOD_S / (EXCITATION_WASHOUT_S + EXCITATION_PERIOD_S)
        self.reset()

    def reset(self) -> None:
        """Back to the start of the sequence: a step on, its first half-period 0.6 s, the washout settled at
        zero."""
        # half-periods of 6 calls, then 10, 9, ... 2, then 6, 5, ... 2 over and over
        self.steps, self.max_steps, self.on, self.low_pass = 5, 10, True, 0.0

    def advance(self) -> float:
        """The next rate setpoint to add (rad/s): the step washed out by its low pass, one call per
        :data:`EXCITATION_PERIOD_S`."""
        if self.steps > self.max_steps:
            self.on, self.steps = not self.on, 0
            self.max_steps = self.max_steps - 1 if self.max_steps > 1 else 5
        self.steps += 1
        step = self.amplitude if self.on else 0.0
        signal = step - self.low_pass
        self.low_pass += self.alpha * (step - self.low_pass)
        return signal


class SecondOrderLowPass:
    """A second-order Butterworth low pass (bilinear transform, prewarped; direct form II) of cutoff
    ``cutoff_hz`` at ``sample_hz``; a cutoff of None, 0 or at or above Nyquist passes the signal
    through (as PX4's LowPassFilter2p)."""

    def __init__(self, sample_hz: float, cutoff_hz: float | None) -> None:
        self.active = cutoff_hz is not None and 0.0 < cutoff_hz < sample_hz / 2.0
        if self.active:
            k = math.tan(math.pi * cutoff_hz / sample_hz)
            norm = 1.0 / (1.0 + math.sqrt(2.0) * k + k * k)
            self.b0 = k * k * norm
            self.b1 = 2.0 * self.b0
            self.a1 = 2.0 * (k * k - 1.0) * norm
            self.a2 = (1.0 - math.sqrt(2.0) * k + k * k) * norm
        self.d1 = self.d2 = 0.0

    def reset(self, value: float) -> None:
        """Settled on ``value``."""
        if self.active:
            self.d1 = self.d2 = value / (1.0 + self.a1 + self.a2)

    def apply(self, x: float) -> float:
        """One sample ``x`` through the filter; the filtered value (``x`` itself when the filter is
        inactive)."""
        if not self.active:
            return x
        d0 = x - self.a1 * self.d1 - self.a2 * self.d2
        y = self.b0 * (d0 + self.d2) + self.b1 * self.d1
        self.d2, self.d1 = self.d1, d0
        return y


class ArxRls:
    """Recursive least squares of the ARX model ``y(k) = -a1 y(k-1) - a2 y(k-2) + b0 u(k-1) +
    b1 u(k-2) + b2 u(k-3)`` (``order`` 2, PX4's) or ``y(k) = -a1 y(k-1) + b0 u(k-1)`` (``order``
    1) with forgetting factor ``forgetting`` (module docstring, step 2). :attr:`theta` is
    ``(a1, a2, b0, b1, b2)`` (order 1: a2 = b1 = b2 = 0); the update starts once the regressors
    hold data."""

    def __init__(self, forgetting: float = 1.0, order: int = 2) -> None:
        if order not in (1, 2):
            raise ValueError(f"model order {order}: 1 or 2")
        self.forgetting, self.order = forgetting, order
        self.reset()

    def reset(self) -> None:
        """The covariance back to :data:`INITIAL_VARIANCE` times identity, the coefficients and the regressors
        to zero (PX4's ``ArxRls::reset``)."""
        n = 5 if self.order == 2 else 2
        self.P = np.eye(n) * INITIAL_VARIANCE
        self.estimate = np.zeros(n)
        self.u = [0.0, 0.0, 0.0, 0.0]  # u(k-3) .. u(k)
        self.y = [0.0, 0.0, 0.0]  # y(k-2) .. y(k)
        self.samples = 0

    def update(self, u: float, y: float) -> None:
        """One RLS step on the input ``u`` (normalised torque) and output ``y`` (body rate, rad/s) of this
        sample; the first five samples only fill the regressors."""
        self.u = self.u[1:] + [u]
        self.y = self.y[1:] + [y]
        if self.samples < 5:  # the regressors still hold zeros (PX4's isBufferFull)
            self.samples += 1
            return
        if self.order == 2:
            phi = np.array((-self.y[1], -self.y[0], self.u[2], self.u[1], self.u[0]))
        else:
            phi = np.array((-self.y[1], self.u[2]))
        p_phi = self.P @ phi
        lam = self.forgetting
        self.P = (self.P - np.outer(p_phi, p_phi) / (lam + phi @ p_phi)) / lam
        self.estimate = self.estimate + self.P @ phi * (self.y[2] - phi @ self.estimate)

    @property
    def theta(self) -> tuple[float, float, float, float, float]:
        """``(a1, a2, b0, b1, b2)``."""
        e = [float(v) for v in self.estimate]
        return (e[0], e[1], e[2], e[3], e[4]) if self.order == 2 else (e[0], 0.0, e[1], 0.0, 0.0)

    @property
    def variances(self) -> np.ndarray:
        """The variance of each coefficient (the diagonal of the RLS covariance), in :attr:`theta`'s order."""
        return np.diag(self.P)


def model_period(sample_dt_s: float, gyro_cutoff_hz: float | None) -> tuple[float, int]:
    """PX4's model sampling period for samples every ``sample_dt_s``: ``max(1 / (2 cutoff),
    sample_dt_s)`` within [2, 10] ms, as a whole number of samples; (period s, samples)."""
    wanted = sample_dt_s if gyro_cutoff_hz is None else max(1.0 / (2.0 * gyro_cutoff_hz), sample_dt_s)
    wanted = min(max(wanted, MODEL_DT_MIN_S), MODEL_DT_MAX_S)
    every = max(int(wanted / sample_dt_s + 1e-9), 1)
    return every * sample_dt_s, every


@dataclass(frozen=True)
class AxisModel:
    """An identified axis: ``y(k) = -a1 y(k-1) - a2 y(k-2) + b0 u(k-1) + b1 u(k-2) + b2 u(k-3)``,
    ``u`` the normalised torque, ``y`` the body rate (rad/s), ``k`` counting ``dt_s``; with the
    variances of the coefficients and the identification's duration."""

    a: tuple[float, float]
    b: tuple[float, float, float]
    dt_s: float
    variances: tuple[float, ...]
    duration_s: float

    def frequency_response(self, frequency_hz: float) -> complex:
        """The model's response (rad/s per unit normalised torque) at ``frequency_hz``."""
        z = cmath.exp(2j * math.pi * frequency_hz * self.dt_s)
        b0, b1, b2 = self.b
        a1, a2 = self.a
        return (b0 + b1 / z + b2 / z**2) / ((1.0 + a1 / z + a2 / z**2) * z)


class AxisIdentification:
    """Step 2 of the module docstring on one axis: :meth:`update` with every sample (the normalised
    torque the rate controller gave, the body rate it was computed from); ``order``: the ARX
    model's (2, PX4's, or 1)."""

    def __init__(self, sample_dt_s: float, gyro_cutoff_hz: float | None, input_scale: float,
                 order: int = 2) -> None:  # fmt: skip
        sample_hz = 1.0 / sample_dt_s
        self.input_scale = input_scale
        self.model_dt_s, self.every = model_period(sample_dt_s, gyro_cutoff_hz)
        self.rls = ArxRls(1.0 - self.model_dt_s / FORGETTING_TIME_S, order)
        self.u_low = SecondOrderLowPass(sample_hz, gyro_cutoff_hz)
        self.y_low = SecondOrderLowPass(sample_hz, gyro_cutoff_hz)
        self.high_alpha = sample_hz / (sample_hz + 2.0 * math.pi * HIGH_PASS_HZ)
        self.samples = 0
        self.started = False

    def update(self, torque: float, rate_rad_s: float) -> None:
        """One sample: ``torque`` the rate controller's normalised output on this axis, ``rate_rad_s`` the
        body rate; both low-passed and high-passed, the RLS fed every ``every``-th sample."""
        u = self.input_scale * torque
        if not self.started:  # the filters start settled on the first sample
            self.u_low.reset(u)
            self.y_low.reset(rate_rad_s)
            self.u_prev, self.y_prev, self.u_high, self.y_high = u, rate_rad_s, 0.0, 0.0
            self.started = True
            return
        u_low, y_low = self.u_low.apply(u), self.y_low.apply(rate_rad_s)
        self.u_high = self.high_alpha * (self.u_high + u_low - self.u_prev)
        self.y_high = self.high_alpha * (self.y_high + y_low - self.y_prev)
        self.u_prev, self.y_prev = u_low, y_low
        self.samples += 1
        if self.samples % self.every == 0:
            self.rls.update(self.u_high, self.y_high)

    def converged(self) -> bool:
        """True when every coefficient's variance is below :data:`CONVERGED_VARIANCE` (PX4's test; the caller
        also waits :data:`MIN_AXIS_TIME_S`)."""
        return bool(np.all(self.rls.variances < CONVERGED_VARIANCE))

    def model(self, duration_s: float) -> AxisModel:
        """The identified model, its input scaled back to the normalised torque."""
        a1, a2, b0, b1, b2 = self.rls.theta
        s = self.input_scale
        return AxisModel((a1, a2), (b0 * s, b1 * s, b2 * s), self.model_dt_s,
                         tuple(float(v) for v in self.rls.variances), duration_s)  # fmt: skip


@dataclass(frozen=True)
class AxisGains:
    """PX4's gains of one axis, ideal form ``u = kc (e + ki integral(e) + kd e')`` (kc, ki in 1/s,
    kd in s) and the attitude P gain (1/s); :attr:`parallel` gives MC_*RATE_P, _I, _D."""

    kc: float
    ki: float
    kd: float
    attitude_p: float

    @property
    def parallel(self) -> tuple[float, float, float]:
        """The gains in PX4's parallel form, ``(MC_*RATE_P, MC_*RATE_I, MC_*RATE_D) = (kc, kc ki, kc kd)``
        (with MC_*RATE_K = 1)."""
        return self.kc, self.kc * self.ki, self.kc * self.kd


def gmvc_pid(
    model: AxisModel, rise_time_s: float, damping_index: float = DAMPING_INDEX, detuning: float = DETUNING
) -> tuple[float, float, float]:
    """The PID of generalised minimum variance control for ``model`` (Yamamoto et al. 1998), as
    PX4 designs it: ``(kc, ki, kd)`` of ``u = kc (e + ki integral(e) + kd e')``.

    The wanted closed loop is ``P(z^-1) = 1 + p1 z^-1 + p2 z^-2``, the discretised second-order
    system of rise time ``sigma`` (``rise_time_s``, within [0.01, 1] s) and damping index
    ``delta`` (0 critical, 1 Butterworth): ``rho = dt / sigma``, ``mu = 0.25 (1 - delta) +
    0.51 delta``, ``p1 = -2 exp(-rho / 2 mu) cos(sqrt(4 mu - 1) rho / 2 mu)``,
    ``p2 = exp(-rho / mu)``. The Diophantine equation ``P = Delta A E + z^-2 F`` (``Delta = 1 -
    z^-1``, ``E = 1 + e1 z^-1``, ``F = f0 + f1 z^-1 + f2 z^-2``) gives ``e1 = p1 + 1 - a1`` and
    the ``f``; the velocity-form PID ``nu Delta u(k) = F(1) r(k) - F(z^-1) y(k)`` with
    ``nu = lambda + E(1) B(1)`` (``lambda``: ``detuning``, which lowers kc only) reads
    ``kc = -(f1 + 2 f2) / nu``, ``ki = -(f0 + f1 + f2) / (dt (f1 + 2 f2))``,
    ``kd = -dt f2 / (f1 + 2 f2)``. PX4 then divides ki by 5 ("required to produce reasonable
    gains"), and so does this function. A D gain just below zero (above -0.001) is zero.
    """
    dt = model.dt_s
    sigma = min(max(rise_time_s, 0.01), 1.0)
    delta = min(max(damping_index, 0.0), 1.0)
    a1, a2 = model.a
    rho = dt / sigma
    mu = 0.25 * (1.0 - delta) + 0.51 * delta
    p1 = -2.0 * math.exp(-rho / (2.0 * mu)) * math.cos(math.sqrt(4.0 * mu - 1.0) * rho / (2.0 * mu))
    p2 = math.exp(-rho / mu)
    e1 = p1 + 1.0 - a1
    f0 = p2 - a2 + a1 + e1 * (1.0 - a1)
    f1 = a2 + e1 * (a1 - a2)
    f2 = e1 * a2
    nu = detuning + (1.0 + e1) * sum(model.b)
    if abs(nu) < 1e-12 or abs(f1 + 2.0 * f2) < 1e-12:
        return 0.0, 0.0, 0.0
    kc = -(f1 + 2.0 * f2) / nu
    ki = -(f0 + f1 + f2) / (dt * (f1 + 2.0 * f2)) / 5.0
    kd = -dt * f2 / (f1 + 2.0 * f2)
    if -0.001 < kd < 0.0:
        kd = 0.0
    return kc, ki, kd


def attitude_gain(kc: float) -> float:
    """PX4's empirical attitude P gain: ``1 / (rad(60) kc)`` within [2, 6.5]."""
    lo, hi = ATTITUDE_P_RANGE
    return min(max(1.0 / (FULL_OUTPUT_ERROR_RAD * kc), lo), hi) if kc > 0.0 else lo


def axis_gains(model: AxisModel, rise_time_s: float) -> AxisGains:
    """The gains of one identified axis: the GMVC PID for the closed-loop rise time ``rise_time_s``
    (:func:`gmvc_pid`) and the attitude P gain from its kc (:func:`attitude_gain`)."""
    kc, ki, kd = gmvc_pid(model, rise_time_s)
    return AxisGains(kc, ki, kd, attitude_gain(kc))


def gains_are_good(gains: tuple[AxisGains, ...]) -> bool:
    """PX4's check before it saves: every kc, ki, attitude P positive and kd not negative; kc below
    0.5, ki below 10, kd below 0.1, attitude P below 12."""
    return all(0.0 < g.kc < 0.5 and 0.0 < g.ki < 10.0 and 0.0 <= g.kd < 0.1 and 0.0 < g.attitude_p < 12.0
               for g in gains)  # fmt: skip
