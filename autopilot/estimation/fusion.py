"""The measurements into the filter, written once as kernels: their models and noise, the gates,
the batch update of GNSS, barometer, magnetometer and vision, and the injection of the error into
the nominal state.

Each fusion finds the state at its measurement's time of validity in the delayed-state buffer
(:func:`.filter.state_at`), builds its rows (Jacobians ``H``, noise variances, innovations), and
hands them to :func:`fuse`: the gates on the prior, then one Joseph update
(:func:`.kernels.joseph_update`) and the injection (:func:`inject`). Its quality checks and
resets are :mod:`.checks`'; the filter's memory and its layouts :mod:`.filter`'s. What a frame
fuses, in PX4's order: :func:`.aiding.fuse_frame`.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from quadcommon.frames import wrap_pi
from quadcommon.kernel import kernel, matrix_view
from quadcommon.layout import quaternion_at, set_quaternion_at, set_vector_at, vector_at
from quadcommon.rigid_body import (
    Quaternion,
    Vector3,
    euler_from_quaternion,
    quaternion_exp,
    quaternion_multiply,
    quaternion_normalised,
    rotation_from_quaternion,
)

from .checks import (
    check_vertical_accel,
    gps_usable,
    mag_checks,
    maybe_reset_position,
    window_append,
    window_of,
)
from .filter import (
    MAX_GROUPS,
    MAX_ROWS,
    MEMORY,
    PARAMETERS,
    SCRATCH,
    STATS,
    FilterArrays,
    state_at,
    world_force,
)
from .kernels import IBA, IBG, IBH, IBM, IP, ITH, IV, N, joseph_update, prior_variances
from .parameters import (  # the EKF2_* bit fields and values, defined with the parameters
    EV_CTRL_HPOS,
    EV_CTRL_VEL,
    EV_CTRL_VPOS,
    EV_CTRL_YAW,
    GPS_CTRL_HPOS,
    GPS_CTRL_VEL,
    GPS_CTRL_VPOS,
    MAG_TYPE_HEADING,
    MAG_TYPE_NONE,
)
from .status import SOURCE

MIN_VARIANCE = 1e-12  # floor of a scalar innovation variance (guards a degenerate P)


class FieldModel(NamedTuple):
    """The magnetometer's model at an attitude (:func:`mag_model`)."""

    field_gauss: Vector3  # predicted body field R^T m_e + b_m
    jacobian: tuple[Vector3, Vector3, Vector3]  # on the global attitude error: R^T [m_e]_x


# =================================================================================================
# Measurement models and noise
# =================================================================================================
@kernel
def yaw_of(q: Quaternion) -> float:
    """The paper's psi of a body-to-world quaternion (ZYX Euler): ``atan2(R10, R00)`` with the two
    entries of :func:`~quadcommon.rigid_body.rotation_from_quaternion` it reads (per fusion)."""
    w, x, y, z = q
    return math.atan2(2.0 * (x * y + w * z), 1.0 - 2.0 * (y * y + z * z))


@kernel
def yaw_jacobian(q: Quaternion) -> Vector3:
    """d psi / d dtheta for the global angular error (``R <- (I + [dtheta]_x) R``).

    With ``psi = atan2(R10, R00)``: ``dR00 = -dth_z R10 + dth_y R20``, ``dR10 = dth_z R00 -
    dth_x R20``, so ``dpsi = dth_z - (R00 R20 dth_x + R10 R20 dth_y) / (R00^2 + R10^2)``.
    """
    R = rotation_from_quaternion(q[0], q[1], q[2], q[3])
    r00, r10, r20 = R[0][0], R[1][0], R[2][0]
    d = r00 * r00 + r10 * r10
    if d < 1e-9:  # pitch at +-90 deg: yaw undefined; fall back to the level-flight Jacobian
        return (0.0, 0.0, 1.0)
    return (-r00 * r20 / d, -r10 * r20 / d, 1.0)


@kernel
def mag_model(q: Quaternion, earth_field: Vector3, bias: Vector3) -> FieldModel:
    """Predicted body field ``R^T m_e + b_m`` and its Jacobian ``R^T [m_e]_x`` on the global
    attitude error (``R <- (I + [dtheta]_x) R`` gives ``R^T m_e <- R^T m_e + R^T [m_e]_x dtheta``);
    the Jacobian on ``b_m`` is the identity."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rotation_from_quaternion(q[0], q[1], q[2], q[3])
    ex, ey, ez = earth_field
    pred = (
        r00 * ex + r10 * ey + r20 * ez + bias[0],
        r01 * ex + r11 * ey + r21 * ez + bias[1],
        r02 * ex + r12 * ey + r22 * ez + bias[2],
    )
    # Row i of R^T [m_e]_x is (column i of R) x m_e.
    H = (
        (r10 * ez - r20 * ey, r20 * ex - r00 * ez, r00 * ey - r10 * ex),
        (r11 * ez - r21 * ey, r21 * ex - r01 * ez, r01 * ey - r11 * ex),
        (r12 * ez - r22 * ey, r22 * ex - r02 * ez, r02 * ey - r12 * ex),
    )
    return FieldModel(pred, H)


@kernel
def mag_heading(A: Any, m: Vector3, phi: float, theta: float, bias: Vector3) -> float:
    """The yaw that turns the tilt-compensated body field onto the earth field's heading."""
    cx, cy, cz = m[0] - bias[0], m[1] - bias[1], m[2] - bias[2]
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    # Level-frame field: Ry(theta) Rx(phi) m (yaw left out).
    lx = ct * cx + st * sf * cy + st * cf * cz
    ly = cf * cy - sf * cz
    return wrap_pi(A[PARAMETERS.field_heading] - math.atan2(ly, lx))


@kernel
def gps_variances(A: Any, eph: float, epv: float, speed_accuracy: float) -> Vector3:
    """Horizontal, vertical position and velocity variances of a fix: the reported accuracies
    with the parameters as floors (PX4: the vertical floor 1.5x the horizontal)."""
    h = max(eph, A[PARAMETERS.gps_pos_noise_m])
    v = max(epv, 1.5 * A[PARAMETERS.gps_pos_noise_m])
    s = max(speed_accuracy, A[PARAMETERS.gps_vel_noise_m_s])
    return (h * h, v * v, s * s)


@kernel
def ev_pos_variance(A: Any, position_std: float) -> float:
    """EKF2_EV_NOISE_MD 0: the reported 1-sigma with EKF2_EVP_NOISE as its floor; 1: the parameter."""
    s = (
        A[PARAMETERS.ev_pos_noise_m]
        if A[PARAMETERS.ev_noise_mode] != 0.0
        else max(position_std, A[PARAMETERS.ev_pos_noise_m])
    )
    return s * s


@kernel
def ev_vel_variance(A: Any, velocity_std: float) -> float:
    """EKF2_EV_NOISE_MD 0: the reported 1-sigma with EKF2_EVV_NOISE as its floor; 1: the parameter."""
    s = (
        A[PARAMETERS.ev_vel_noise_m_s]
        if A[PARAMETERS.ev_noise_mode] != 0.0
        else max(velocity_std, A[PARAMETERS.ev_vel_noise_m_s])
    )
    return s * s


@kernel
def ev_yaw_variance(A: Any, yaw_std: float) -> float:
    """A vision yaw's variance (rad^2): EKF2_EVA_NOISE alone (EKF2_EV_NOISE_MD 1), else the larger of
    it and the sample's own standard deviation ``yaw_std``."""
    s = (
        A[PARAMETERS.ev_yaw_noise_rad]
        if A[PARAMETERS.ev_noise_mode] != 0.0
        else max(yaw_std, A[PARAMETERS.ev_yaw_noise_rad])
    )
    return s * s


class MeasurementRows(NamedTuple):
    """One measurement's rows for :func:`fuse` (m rows, the error state's N columns)."""

    H: np.ndarray  # m x N: each row's Jacobian in the error state
    r: np.ndarray  # m: each row's noise variance
    y: np.ndarray  # m: each row's innovation
    group: np.ndarray  # m: each row's group (a kind's axes gated together)


class Groups(NamedTuple):
    """The groups of a measurement's rows: what each is and its gate; :func:`fuse` writes whether
    each passed."""

    source: np.ndarray  # each group's row of figures (SOURCE)
    gate: np.ndarray  # each group's gate (standard deviations)
    accepted: np.ndarray  # out: 1.0 fused, 0.0 rejected


@kernel
def measurement_rows(scratch: Any, m: int) -> MeasurementRows:
    """``m`` rows cut from the memory's scratch (:data:`.filter.SCRATCH`), H and the groups zeroed."""
    H = matrix_view(scratch, SCRATCH.H, m, N)
    H[:] = 0.0
    group = scratch[SCRATCH.row_group : SCRATCH.row_group + m]
    group[:] = 0.0
    return MeasurementRows(H, scratch[SCRATCH.r : SCRATCH.r + m], scratch[SCRATCH.y : SCRATCH.y + m], group)


@kernel
def measurement_groups(scratch: Any, g: int) -> Groups:
    """``g`` groups cut from the memory's scratch, none accepted yet."""
    accepted = scratch[SCRATCH.accepted : SCRATCH.accepted + g]
    accepted[:] = 0.0
    return Groups(scratch[SCRATCH.group_source : SCRATCH.group_source + g],
                  scratch[SCRATCH.group_gate : SCRATCH.group_gate + g], accepted)  # fmt: skip


@kernel
def one_group(scratch: Any, source: int, gate: float) -> Groups:
    """The one group of a measurement gated as a whole: its ``source`` (a row of :data:`SOURCE`)
    and ``gate``, cut from the memory's scratch."""
    groups = measurement_groups(scratch, 1)
    groups.source[0], groups.gate[0] = source, gate
    return groups


@kernel
def first_parts(rows: MeasurementRows, k: int, groups: Groups, g: int) -> tuple[MeasurementRows, Groups]:
    """The first ``k`` rows and ``g`` groups (a measurement whose parts are switched off by EKF2_*_CTRL)."""
    H, r, y, group = rows
    return MeasurementRows(H[:k], r[:k], y[:k], group[:k]), Groups(groups.source[:g], groups.gate[:g],
                                                                    groups.accepted[:g])  # fmt: skip


# =================================================================================================
# Gates, update, injection
# =================================================================================================
@kernel
def fuse(memory: FilterArrays, rows: MeasurementRows, groups: Groups) -> None:
    """Gate, then fuse one measurement: its ``rows`` (``H``, m x N, with noise variances ``r``,
    innovations ``y``, each row in group ``group[k]``: groups in order, rows of a group
    consecutive); a group is one kind's axes (``groups.source``, gate ``groups.gate``).

    Each group passes or fails its gate as a whole on the prior innovation variances, as PX4
    does (``groups.accepted`` 1/0 per group); the accepted rows are then fused in one batch, in Joseph
    form (:func:`.kernels.joseph_update`, Solà §6.1), and the error ``K y`` injected
    (:func:`inject`). A batch equals the sequence of scalar updates for a linear ``h`` and costs
    one set of 19x19 products instead of one per axis.
    """
    F, P, _, stats, W, scratch = memory
    H, r, y, row_group = rows
    group_source, group_gate, accepted = groups
    m = H.shape[0]
    n_groups = group_source.shape[0]
    prior = scratch[SCRATCH.prior : SCRATCH.prior + m]
    prior_variances(P, H, prior)
    now = F[MEMORY.time]
    kept = 0
    k = 0
    for g in range(n_groups):
        src = int(group_source[g])
        gate = group_gate[g]
        first = k
        while k < m and int(row_group[k]) == g:
            k += 1
        worst = 0.0
        for j in range(first, k):
            ratio = y[j] * y[j] / (gate * gate * max(prior[j] + r[j], MIN_VARIANCE))
            if ratio > worst:
                worst = ratio
        last = k - 1
        s = stats[src]
        s[STATS.test_ratio] = worst
        s[STATS.innovation] = y[last]
        s[STATS.normalized_innovation] = y[last] / math.sqrt(max(prior[last] + r[last], MIN_VARIANCE))
        s[STATS.last_tested_s] = now
        w = window_of(src)
        if w >= 0:
            window_append(W, w, now, s[STATS.normalized_innovation])
        if worst > 1.0:
            s[STATS.rejected] += 1.0
            s[STATS.last_rejected_s] = now
            if s[STATS.rejecting_since_s] < 0.0:
                s[STATS.rejecting_since_s] = now
            accepted[g] = 0.0
        else:
            s[STATS.rejecting_since_s] = -1.0
            s[STATS.fused] += 1.0
            s[STATS.last_fused_s] = now
            accepted[g] = 1.0
            kept += k - first
    if kept == 0:
        return
    Hk = matrix_view(scratch, SCRATCH.kept_H, kept, N)
    rk = scratch[SCRATCH.kept_r : SCRATCH.kept_r + kept]
    yk = scratch[SCRATCH.kept_y : SCRATCH.kept_y + kept]
    i = 0
    for j in range(m):
        if accepted[int(row_group[j])] != 0.0:
            for c in range(N):
                Hk[i, c] = H[j, c]
            rk[i] = r[j]
            yk[i] = y[j]
            i += 1
    dx = scratch[SCRATCH.dx : SCRATCH.dx + N]
    joseph_update(P, Hk, rk, yk, dx, scratch[SCRATCH.update : SCRATCH.size])
    inject(F, P, dx)


@kernel
def inject(F: Any, P: Any, dx: Any) -> None:
    """Nominal state <- nominal (+) dx (Solà §6.2, global attitude error), then the reset."""
    for i in range(3):
        F[MEMORY.p + i] += dx[IP + i]
        F[MEMORY.v + i] += dx[IV + i]
        F[MEMORY.gyro_bias + i] += dx[IBG + i]
        F[MEMORY.accel_bias + i] += dx[IBA + i]
        F[MEMORY.mag_bias + i] += dx[IBM + i]
        # Bookkeeping for the buffered past states.
        F[MEMORY.correction_p + i] += dx[IP + i]
        F[MEMORY.correction_v + i] += dx[IV + i]
    F[MEMORY.baro_bias] += dx[IBH]
    dq = quaternion_exp(dx[ITH], dx[ITH + 1], dx[ITH + 2])
    set_quaternion_at(F, MEMORY.q, quaternion_normalised(quaternion_multiply(dq, quaternion_at(F, MEMORY.q))))
    set_quaternion_at(F, MEMORY.correction_q, quaternion_multiply(dq, quaternion_at(F, MEMORY.correction_q)))
    # The previous sample's world force and the reported rate follow the new q and biases.
    set_vector_at(F, MEMORY.prev_acc, world_force(F, vector_at(F, MEMORY.prev_force)))
    for i in range(3):
        F[MEMORY.rate + i] = F[MEMORY.prev_rate + i] - F[MEMORY.gyro_bias + i]
    # Reset, Solà §7.3.3: P <- G P G^T with G_theta = I + [dtheta/2]_x. Below 1 mrad, G - I
    # changes P by less than 0.05 %: skipped there (it costs as much as a fusion).
    hx, hy, hz = 0.5 * dx[ITH], 0.5 * dx[ITH + 1], 0.5 * dx[ITH + 2]
    if hx * hx + hy * hy + hz * hz > 0.25e-6:
        for j in range(N):  # rows: G P
            a, b, c = P[ITH, j], P[ITH + 1, j], P[ITH + 2, j]
            P[ITH, j] = a - hz * b + hy * c
            P[ITH + 1, j] = hz * a + b - hx * c
            P[ITH + 2, j] = -hy * a + hx * b + c
        for i in range(N):  # columns: (G P) G^T
            a, b, c = P[i, ITH], P[i, ITH + 1], P[i, ITH + 2]
            P[i, ITH] = a - hz * b + hy * c
            P[i, ITH + 1] = hz * a + b - hx * c
            P[i, ITH + 2] = -hy * a + hx * b + c


# =================================================================================================
# Rows of H
# =================================================================================================
@kernel
def position_rows(rows: MeasurementRows, k: int, g: int, axis: int, D: float, innovation: float,
                  var: float) -> int:  # fmt: skip
    """Row ``k`` (of group ``g``): a position axis measured ``D`` s ago (``dp(t_m) = dp - D dv``);
    the next row."""
    H, r, y, row_group = rows
    H[k, IP + axis] = 1.0
    H[k, IV + axis] = -D
    r[k], y[k], row_group[k] = var, innovation, g
    return k + 1


@kernel
def velocity_row(rows: MeasurementRows, k: int, g: int, axis: int, innovation: float, var: float) -> int:
    """Row ``k`` (of group ``g``): a velocity axis measured directly; the next row."""
    H, r, y, row_group = rows
    H[k, IV + axis] = 1.0
    r[k], y[k], row_group[k] = var, innovation, g
    return k + 1


@kernel
def yaw_row(rows: MeasurementRows, k: int, g: int, q: Quaternion, innovation: float, var: float) -> int:
    """Row ``k`` (of group ``g``): the yaw of the attitude ``q`` through its Jacobian in the
    attitude error; the next row."""
    H, r, y, row_group = rows
    J = yaw_jacobian(q)
    H[k, ITH], H[k, ITH + 1], H[k, ITH + 2] = J[0], J[1], J[2]
    r[k], y[k], row_group[k] = var, innovation, g
    return k + 1


class GnssMeasurement(NamedTuple):
    """What a GNSS fix brings the filter (paper frames; every number a float: one compiled type)."""

    position_m: Vector3  # world, about home
    velocity_m_s: Vector3  # world
    eph_m: float  # reported 1-sigma horizontal position accuracy
    epv_m: float  # reported 1-sigma vertical position accuracy
    speed_accuracy_m_s: float  # 0: unknown
    fix_type: float  # GPS_FIX_TYPE
    satellites: float  # visible


class VisionMeasurement(NamedTuple):
    """What a vision pose brings the filter (paper frames; floats)."""

    position_m: Vector3  # world
    yaw_rad: float  # the paper's psi
    position_std_m: float  # reported 1-sigma per axis (0: unknown)
    yaw_std_rad: float  # (0: unknown)


# =================================================================================================
# The fusions
# =================================================================================================
@kernel
def fuse_gps(memory: FilterArrays, A: Any, t: float, gnss: GnssMeasurement) -> None:
    """GNSS position (horizontal, height) and velocity arrived at ``t``, valid EKF2_GPS_DELAY before."""
    F, P, ring, stats, W, scratch = memory
    position, velocity = gnss.position_m, gnss.velocity_m_s
    eph, epv, speed_accuracy = gnss.eph_m, gnss.epv_m, gnss.speed_accuracy_m_s
    fix_type, satellites = gnss.fix_type, gnss.satellites
    if not gps_usable(A, fix_type, eph, epv, satellites):
        stats[SOURCE.gps_pos, STATS.check_rejected] += 1.0
        return
    past = state_at(F, ring, t - A[PARAMETERS.gps_delay_s])
    if not past.found:
        stats[SOURCE.gps_pos, STATS.too_old] += 1.0
        return
    pm, vm, D = past.position_m, past.velocity_m_s, past.age_s
    hv, vv, sv = gps_variances(A, eph, epv, speed_accuracy)
    ctrl = int(A[PARAMETERS.gps_ctrl])
    rows, groups = measurement_rows(scratch, MAX_ROWS), measurement_groups(scratch, MAX_GROUPS)
    group_source, group_gate, accepted = groups
    k = g = 0
    if ctrl & GPS_CTRL_HPOS:
        k = position_rows(rows, k, g, 0, D, position[0] - pm[0], hv)
        k = position_rows(rows, k, g, 1, D, position[1] - pm[1], hv)
        group_source[g], group_gate[g] = SOURCE.gps_pos, A[PARAMETERS.gps_pos_gate]
        g += 1
    if ctrl & GPS_CTRL_VPOS:
        k = position_rows(rows, k, g, 2, D, position[2] - pm[2], vv)
        group_source[g], group_gate[g] = SOURCE.gps_hgt, A[PARAMETERS.baro_gate]
        g += 1
    if ctrl & GPS_CTRL_VEL:
        # Horizontal and vertical velocity gated apart (as PX4 does), so that a vertical
        # accelerometer fault does not also cut the horizontal aiding.
        k = velocity_row(rows, k, g, 0, velocity[0] - vm[0], sv)
        k = velocity_row(rows, k, g, 1, velocity[1] - vm[1], sv)
        group_source[g], group_gate[g] = SOURCE.gps_vel, A[PARAMETERS.gps_vel_gate]
        g += 1
        k = velocity_row(rows, k, g, 2, velocity[2] - vm[2], sv * 2.25)  # PX4: 1.5x
        group_source[g], group_gate[g] = SOURCE.gps_vvel, A[PARAMETERS.gps_vel_gate]
        g += 1
    if g == 0:
        return
    fused_rows, fused_groups = first_parts(rows, k, groups, g)
    fuse(memory, fused_rows, fused_groups)
    now = F[MEMORY.time]
    for j in range(g):
        src, ok = int(group_source[j]), accepted[j] != 0.0
        if src == SOURCE.gps_pos:
            if ok:
                F[MEMORY.last_h_aid] = now
                F[MEMORY.last_gps_pos] = now
            else:
                target = (position[0] + F[MEMORY.p] - pm[0], position[1] + F[MEMORY.p + 1] - pm[1], 0.0)
                maybe_reset_position(F, P, stats, A, SOURCE.gps_pos, target, hv)
        elif ok and (src in (SOURCE.gps_hgt, SOURCE.gps_vvel)):
            F[MEMORY.last_v_aid] = now
        elif ok and src == SOURCE.gps_vel:
            F[MEMORY.last_h_aid] = now
    check_vertical_accel(F, stats, W)


@kernel
def fuse_baro(memory: FilterArrays, A: Any, t: float, height: float) -> None:
    """Barometric height arrived at ``t``: ``h = z + b_h`` (the offset is a state), at most EKF2_BARO_RATE."""
    F, P, ring, stats, W, scratch = memory
    if A[PARAMETERS.baro_enabled] == 0.0:
        return
    s = stats[SOURCE.baro]
    if t < F[MEMORY.next_baro]:
        s[STATS.skipped] += 1.0
        return
    F[MEMORY.next_baro] = t + A[PARAMETERS.baro_period_s] - 1e-9
    past = state_at(F, ring, t - A[PARAMETERS.baro_delay_s])
    if not past.found:
        s[STATS.too_old] += 1.0
        return
    pm, D = past.position_m, past.age_s
    rows, groups = measurement_rows(scratch, 1), one_group(scratch, SOURCE.baro, A[PARAMETERS.baro_gate])
    H, r, y, _ = rows
    H[0, IP + 2], H[0, IV + 2], H[0, IBH] = 1.0, -D, 1.0
    r[0], y[0] = A[PARAMETERS.baro_noise_m] ** 2, height - pm[2] - F[MEMORY.baro_bias]
    fuse(memory, rows, groups)
    if groups.accepted[0] != 0.0:
        F[MEMORY.last_v_aid] = F[MEMORY.time]
    check_vertical_accel(F, stats, W)


@kernel
def fuse_mag(memory: FilterArrays, A: Any, t: float, m: Vector3) -> None:
    """Magnetometer arrived at ``t``, at most EKF2_MAG_RATE: the 3-axis field ``m = R^T m_earth +
    b_m`` (EKF2_MAG_TYPE 0) or the tilt-compensated heading (1)."""
    F, P, ring, stats, W, scratch = memory
    mag_type = int(A[PARAMETERS.mag_type])
    if mag_type == MAG_TYPE_NONE:
        return
    src = SOURCE.heading if mag_type == MAG_TYPE_HEADING else SOURCE.mag
    if t < F[MEMORY.next_mag]:
        stats[src, STATS.skipped] += 1.0
        return
    F[MEMORY.next_mag] = t + A[PARAMETERS.mag_period_s] - 1e-9
    past = state_at(F, ring, t - A[PARAMETERS.mag_delay_s])
    if not past.found:
        stats[src, STATS.too_old] += 1.0
        return
    q = past.attitude
    if not mag_checks(F, stats, A, src, m, q):
        return
    if mag_type == MAG_TYPE_HEADING:
        rows = measurement_rows(scratch, 1)
        phi, theta, _ = euler_from_quaternion(q[0], q[1], q[2], q[3])
        measured = mag_heading(A, m, phi, theta, vector_at(F, MEMORY.mag_bias))
        yaw_row(rows, 0, 0, q, wrap_pi(measured - yaw_of(q)), A[PARAMETERS.heading_noise_rad] ** 2)
        fuse(memory, rows, one_group(scratch, SOURCE.heading, A[PARAMETERS.heading_gate]))
        return
    pred, J = mag_model(q, vector_at(A, PARAMETERS.field), vector_at(F, MEMORY.mag_bias))
    rows = measurement_rows(scratch, 3)
    H, r, y, _ = rows
    var = A[PARAMETERS.mag_noise_gauss] ** 2
    for i in range(3):
        H[i, ITH], H[i, ITH + 1], H[i, ITH + 2] = J[i][0], J[i][1], J[i][2]
        H[i, IBM + i] = 1.0
        r[i], y[i] = var, m[i] - pred[i]
    fuse(memory, rows, one_group(scratch, SOURCE.mag, A[PARAMETERS.mag_gate]))


@kernel
def fuse_vision(memory: FilterArrays, A: Any, t: float, vision: VisionMeasurement) -> None:
    """Motion capture / vision position and yaw arrived at ``t``, valid EKF2_EV_DELAY before."""
    F, P, ring, stats, W, scratch = memory
    position, yaw = vision.position_m, vision.yaw_rad
    position_std, yaw_std = vision.position_std_m, vision.yaw_std_rad
    past = state_at(F, ring, t - A[PARAMETERS.ev_delay_s])
    if not past.found:
        stats[SOURCE.ev_pos, STATS.too_old] += 1.0
        return
    pm, qm, D = past.position_m, past.attitude, past.age_s
    var = ev_pos_variance(A, position_std)
    ctrl = int(A[PARAMETERS.ev_ctrl])
    rows, groups = measurement_rows(scratch, 4), measurement_groups(scratch, 3)
    group_source, group_gate, accepted = groups
    k = g = 0
    if ctrl & EV_CTRL_HPOS:
        k = position_rows(rows, k, g, 0, D, position[0] - pm[0], var)
        k = position_rows(rows, k, g, 1, D, position[1] - pm[1], var)
        group_source[g], group_gate[g] = SOURCE.ev_pos, A[PARAMETERS.ev_pos_gate]
        g += 1
    if ctrl & EV_CTRL_VPOS:
        k = position_rows(rows, k, g, 2, D, position[2] - pm[2], var)
        group_source[g], group_gate[g] = SOURCE.ev_hgt, A[PARAMETERS.ev_pos_gate]
        g += 1
    if ctrl & EV_CTRL_YAW:
        k = yaw_row(rows, k, g, qm, wrap_pi(yaw - yaw_of(qm)), ev_yaw_variance(A, yaw_std))
        group_source[g], group_gate[g] = SOURCE.ev_yaw, A[PARAMETERS.heading_gate]
        g += 1
    if g == 0:
        return
    fused_rows, fused_groups = first_parts(rows, k, groups, g)
    fuse(memory, fused_rows, fused_groups)
    now = F[MEMORY.time]
    for j in range(g):
        src, ok = int(group_source[j]), accepted[j] != 0.0
        if src == SOURCE.ev_pos:
            if ok:
                F[MEMORY.last_h_aid] = now
            else:
                target = (position[0] + F[MEMORY.p] - pm[0], position[1] + F[MEMORY.p + 1] - pm[1], 0.0)
                maybe_reset_position(F, P, stats, A, SOURCE.ev_pos, target, var)
        elif ok and src == SOURCE.ev_hgt:
            F[MEMORY.last_v_aid] = now
    check_vertical_accel(F, stats, W)


@kernel
def fuse_vision_velocity(memory: FilterArrays, A: Any, t: float, velocity: Vector3,
                         velocity_std: float) -> None:  # fmt: skip
    """External vision velocity (world, paper frame) arrived at ``t``, valid EKF2_EV_DELAY before:
    the three axes gated together (EKF2_EVV_GATE), as PX4's EKF2 fuses ``ev_vel`` when
    EKF2_EV_CTRL bit 2 is set. Accepted, it is horizontal aiding (no dead reckoning)."""
    F, P, ring, stats, W, scratch = memory
    if not int(A[PARAMETERS.ev_ctrl]) & EV_CTRL_VEL:
        return
    past = state_at(F, ring, t - A[PARAMETERS.ev_delay_s])
    if not past.found:
        stats[SOURCE.ev_vel, STATS.too_old] += 1.0
        return
    vm = past.velocity_m_s
    var = ev_vel_variance(A, velocity_std)
    rows, groups = measurement_rows(scratch, 3), one_group(scratch, SOURCE.ev_vel, A[PARAMETERS.ev_vel_gate])
    k = 0
    for axis in range(3):
        k = velocity_row(rows, k, 0, axis, velocity[axis] - vm[axis], var)
    fuse(memory, rows, groups)
    if groups.accepted[0] != 0.0:
        F[MEMORY.last_h_aid] = F[MEMORY.time]
    check_vertical_accel(F, stats, W)
