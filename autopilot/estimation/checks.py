"""The quality checks and resets the fusions call, written once as kernels: a GNSS fix's quality
(EKF2_REQ_EPH, EKF2_REQ_EPV, EKF2_REQ_NSATS), the magnetic field checks (EKF2_MAG_CHECK), the
bad-vertical-acceleration check over its windows of normalised innovations, and the horizontal
position reset after a run of rejections (EST_POS_RST_T). The filter's memory and its layouts are
:mod:`.filter`'s.
"""

from __future__ import annotations

import math
from typing import Any

from quadcommon.kernel import kernel
from quadcommon.rigid_body import Quaternion, Vector3, rotation_from_quaternion

from .filter import INNOVATION_WINDOWS, MEMORY, PARAMETERS, STATS, WINDOW, WINDOW_ROW
from .kernels import IP, N
from .parameters import MAG_CHECK_INCLINATION, MAG_CHECK_STRENGTH
from .status import SOURCE

GPS_FIX_3D = 3
# Bad vertical acceleration (PX4's bad_acc_vertical): vertical velocity and height innovations
# both gated out with the same sign mean the accelerometer, not the aiding, is wrong. Then, for
# BAD_ACCEL_HOLD_S, the prediction inflates the vertical velocity's and the z accelerometer bias's
# variances (:data:`.filter.BAD_ACCEL_VEL_DENSITY`).
BAD_ACCEL_HOLD_S = 1.0
BAD_ACCEL_WINDOW_S = 1.0  # the mean of the normalised vertical innovations over this window ...
BAD_ACCEL_MEAN = 1.5  # ... beyond this (4.7 sigma of the mean of 10 GPS fixes)
BAD_ACCEL_MIN_SAMPLES = 8


# =================================================================================================
# Quality of a sample
# =================================================================================================
@kernel
def gps_usable(A: Any, fix_type: float, eph: float, epv: float, satellites: float) -> bool:
    """A fix the filter may fuse or align on: 3D, its accuracies within EKF2_REQ_EPH / EKF2_REQ_EPV,
    at least EKF2_REQ_NSATS satellites."""
    return (
        fix_type >= GPS_FIX_3D
        and eph <= A[PARAMETERS.gps_req_eph_m]
        and epv <= A[PARAMETERS.gps_req_epv_m]
        and satellites >= A[PARAMETERS.gps_req_nsats]
    )


@kernel
def mag_checks(F: Any, stats: Any, A: Any, source: int, m: Vector3, q: Quaternion) -> bool:
    """PX4's EKF2_MAG_CHECK: the corrected field's strength and inclination against the model."""
    c = (m[0] - F[MEMORY.mag_bias], m[1] - F[MEMORY.mag_bias + 1], m[2] - F[MEMORY.mag_bias + 2])
    strength = math.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2])
    check = int(A[PARAMETERS.mag_check])
    ok = True
    if (
        check & MAG_CHECK_STRENGTH
        and abs(strength - A[PARAMETERS.field_strength]) > A[PARAMETERS.mag_strength_tol_gauss]
    ):
        ok = False
    if ok and check & MAG_CHECK_INCLINATION and strength > 0.0:
        R = rotation_from_quaternion(q[0], q[1], q[2], q[3])
        wz = R[2][0] * c[0] + R[2][1] * c[1] + R[2][2] * c[2]
        inclination = math.asin(max(-1.0, min(1.0, -wz / strength)))
        ok = abs(inclination - A[PARAMETERS.field_inclination]) <= A[PARAMETERS.mag_inclination_tol_rad]
    if not ok:
        stats[source, STATS.check_rejected] += 1.0
        stats[source, STATS.last_rejected_s] = F[MEMORY.time]
    return ok


# =================================================================================================
# The innovation windows and the bad-vertical-acceleration check
# =================================================================================================
@kernel
def window_append(W: Any, w: int, t: float, value: float) -> None:
    """``(t, value)`` into window ``w`` (the oldest goes when full); its running sum is summed
    again every ``WINDOW`` appends, so round-off cannot build up."""
    row = W[w]
    start, count = int(row[WINDOW_ROW.start]), int(row[WINDOW_ROW.count_held])
    if count >= WINDOW:
        row[WINDOW_ROW.total] -= row[WINDOW_ROW.values + start]
        start = (start + 1) % WINDOW
        count -= 1
    i = (start + count) % WINDOW
    row[WINDOW_ROW.times + i] = t
    row[WINDOW_ROW.values + i] = value
    count += 1
    row[WINDOW_ROW.total] += value
    row[WINDOW_ROW.start], row[WINDOW_ROW.count_held] = start, count
    row[WINDOW_ROW.appends] += 1.0
    if row[WINDOW_ROW.appends] >= WINDOW:
        row[WINDOW_ROW.appends] = 0.0
        total = 0.0
        for j in range(count):
            total += row[WINDOW_ROW.values + (start + j) % WINDOW]
        row[WINDOW_ROW.total] = total


@kernel
def window_mean_since(W: Any, w: int, t: float) -> tuple[int, float]:
    """Drop the samples of window ``w`` older than ``t``; ``(samples left, their mean)``."""
    row = W[w]
    start, count = int(row[WINDOW_ROW.start]), int(row[WINDOW_ROW.count_held])
    while count > 0 and row[WINDOW_ROW.times + start] < t:
        row[WINDOW_ROW.total] -= row[WINDOW_ROW.values + start]
        start = (start + 1) % WINDOW
        count -= 1
    row[WINDOW_ROW.start], row[WINDOW_ROW.count_held] = start, count
    return count, (row[WINDOW_ROW.total] / count if count > 0 else 0.0)


@kernel
def window_of(source: int) -> int:
    """The innovation window a kind feeds (-1: none)."""
    if source == SOURCE.gps_vvel:
        return INNOVATION_WINDOWS.gps_vvel
    if source == SOURCE.ev_hgt:
        return INNOVATION_WINDOWS.ev_hgt
    return -1


@kernel
def check_vertical_accel(F: Any, stats: Any, W: Any) -> None:
    """Bad vertical acceleration (PX4's bad_acc_vertical, made statistical): the mean of the
    normalised vertical velocity innovations (GPS) over the last BAD_ACCEL_WINDOW_S is beyond
    BAD_ACCEL_MEAN and the height innovation agrees in sign; or, without a velocity source,
    the mean of the normalised vision height innovations is. For a consistent filter the
    mean of n samples has a standard deviation 1/sqrt(n) (0.32 at 10 GPS fixes): by chance
    the test fires about once in 10^5 windows; a vertical accelerometer fault (a bias step the
    random-walk model cannot follow) trips it within about a second."""
    now = F[MEMORY.time]
    bad = False
    if stats[SOURCE.gps_vvel, STATS.last_tested_s] == now:
        n, mean = window_mean_since(W, INNOVATION_WINDOWS.gps_vvel, now - BAD_ACCEL_WINDOW_S)
        if n >= BAD_ACCEL_MIN_SAMPLES and abs(mean) >= BAD_ACCEL_MEAN:
            # The height source tested last (GNSS height first on a tie) agrees in sign.
            hgt, baro = stats[SOURCE.gps_hgt], stats[SOURCE.baro]
            latest = -1
            if hgt[STATS.last_tested_s] >= 0.0:
                latest = SOURCE.gps_hgt
            if baro[STATS.last_tested_s] >= 0.0 and (
                latest < 0 or baro[STATS.last_tested_s] > hgt[STATS.last_tested_s]
            ):
                latest = SOURCE.baro
            bad = latest >= 0 and stats[latest, STATS.innovation] * mean > 0.0
    if stats[SOURCE.ev_hgt, STATS.last_tested_s] == now:
        n, mean = window_mean_since(W, INNOVATION_WINDOWS.ev_hgt, now - BAD_ACCEL_WINDOW_S)
        if n >= BAD_ACCEL_MIN_SAMPLES and abs(mean) >= BAD_ACCEL_MEAN:
            bad = True
    if bad:
        if now >= F[MEMORY.bad_accel_until]:
            F[MEMORY.bad_accel_detections] += 1.0
        F[MEMORY.bad_accel_until] = now + BAD_ACCEL_HOLD_S


# =================================================================================================
# Reset
# =================================================================================================
@kernel
def maybe_reset_position(
    F: Any, P: Any, stats: Any, A: Any, source: int, target: Vector3, var: float
) -> None:
    """After EST_POS_RST_T of continuous rejections of a good source, the horizontal position
    jumps to it (PX4 does)."""
    s = stats[source]
    since = s[STATS.rejecting_since_s]
    if since < 0.0 or F[MEMORY.time] - since < A[PARAMETERS.pos_reset_timeout_s]:
        return
    for i in range(2):
        delta = target[i] - F[MEMORY.p + i]
        F[MEMORY.p + i] += delta
        F[MEMORY.correction_p + i] += delta
        for j in range(N):
            P[IP + i, j] = 0.0
            P[j, IP + i] = 0.0
        P[IP + i, IP + i] = var
    s[STATS.resets] += 1.0
    s[STATS.rejecting_since_s] = -1.0
