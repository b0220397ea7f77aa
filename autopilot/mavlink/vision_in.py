"""External vision in: a client's VISION_POSITION_ESTIMATE and ODOMETRY for the EKF (pure: the
caller gives the times).

A motion-capture bridge or a VIO on a companion computer sends the vehicle's pose on a
ground-station link, as to PX4. :class:`ExternalVision` reads each message as PX4's MAVLink
receiver does, checks it at the edge, times it, and hands the filter a
:class:`~autopilot.records.VisionPose`, which the EKF fuses through the same vision
fusion as the simulator's own vision stream (EKF2_EV_CTRL, EKF2_EV_DELAY, EKF2_EVP_NOISE,
EKF2_EVA_NOISE, EKF2_EV_NOISE_MD, EKF2_EVP_GATE). What is refused is counted by reason and
announced (:meth:`ExternalVision.announcement`); nothing is dropped unsaid.

How the messages are read (PX4's ``mavlink_receiver.cpp``):

* VISION_POSITION_ESTIMATE: x, y, z in the local NED frame, yaw (roll and pitch are read only to
  be checked: PX4's EKF2 fuses the vision yaw, not its tilt); the covariance's diagonal (x 0, y 6,
  z 11, yaw 20: the row-major upper triangle), a NaN first element meaning unknown;
* ODOMETRY: ``frame_id`` MAV_FRAME_LOCAL_NED or MAV_FRAME_LOCAL_FRD (an earth-fixed frame whose
  x axis points anywhere: read as NED, its forward taken for north; with the vision yaw fused the
  filter's heading follows the vision frame, as PX4's does; PX4 also estimates the rotation
  between the frames when the yaw is not fused, this autopilot does not); the yaw of ``q`` (body
  FRD to ``frame_id``); the pose covariance's diagonal as above, not read for
  MAV_ESTIMATOR_TYPE_NAIVE; ``quality`` below EKF2_EV_QMIN (-1: failed) refused;
  ``estimator_type`` UNKNOWN, NAIVE, VISION or VIO (PX4 publishes them as visual odometry, the
  topic EKF2 reads); MOCAP odometry is refused, as PX4's EKF2 never sees it (PX4 publishes it as
  mocap odometry, which EKF2 does not read: a mocap bridge sends VISION_POSITION_ESTIMATE, or
  ODOMETRY of estimator type VISION); the velocity (``vx``, ``vy``, ``vz``) when it is finite, in
  ``child_frame_id`` MAV_FRAME_BODY_FRD (rotated by ``q``), LOCAL_NED or LOCAL_FRD (as the
  position), with the velocity covariance's diagonal (vx 0, vy 6, vz 11; a NaN first element
  meaning unknown), fused when EKF2_EV_CTRL has bit 2 (EKF2_EVV_NOISE, EKF2_EVV_GATE); another
  ``child_frame_id`` leaves the velocity out, said.

Each position is read as the vision frame's, the filter's local frame (the frame of the EKF's
position: about home when it also fuses GNSS).

Checks at the edge, each refusal counted by its reason: numbers that are not finite; absurd ones
(a position farther than :data:`MAX_DISTANCE_M` from the origin, an angle beyond 2 pi, a
quaternion whose norm is far from 1, a variance that is negative or not finite); an unsupported
frame or estimator type; a flood (more than one sample per control frame: the filter fuses one a
frame, the first); and the times below.

**Time.** A message's ``usec`` / ``time_usec`` is its sender's clock. PX4 maps it to its own
with timesync (it sends TIMESYNC requests and estimates each link's offset) and, until that has
converged, takes the sample at its arrival. This vehicle's clock is the simulation time: its
TIMESYNC answers with it and its telemetry is stamped with it. So a sender's clock is decided
from its first stamp (:class:`SenderClocks`): within :data:`SYNC_WINDOW_S` of the vehicle's time
at arrival, the sender is on the vehicle's clock (it synchronised through TIMESYNC, as MAVSDK's
Mocap plugin does, or it stamps with the vehicle's own telemetry times), and each of its samples
is valid at its stamp: one more than :data:`MAX_FUTURE_S` ahead of the vehicle's time is refused
("in the future"), one older than :data:`MAX_AGE_S` is refused ("too old"), and after
:data:`RELEARN_AFTER` such refusals in a row the sender's clock is decided again (PX4 resets its
timesync after consecutive outliers: a client whose clock drifted). Otherwise the sender is on a
clock of its own (a script's boot time or UNIX time): its samples are valid at their arrival, as
PX4 takes them before its timesync has converged. A stamp of 0 means "at arrival". On either
clock a stamp not later than the sender's previous one is refused (a duplicate, a reordered or
replayed message; these count among the refusals in a row too: a client that restarted its clock).
A restarted simulator (its time starts again) forgets every sender's clock. The filter then takes
the sample as valid EKF2_EV_DELAY before that time.
"""

from __future__ import annotations

import math
from collections import Counter
from typing import NamedTuple

from quadcommon import frames
from quadcommon.rigid_body import euler_from_quaternion, matrix_times, rotation_from_quaternion

from ..records import VisionPose
from .codec import mavlink as m

MAX_DISTANCE_M = 10_000.0  # a vision position farther than this from its origin is absurd
MAX_SPEED_M_S = 100.0  # a vision velocity faster than this is absurd
MAX_ANGLE_RAD = 2.0 * math.pi  # |roll|, |pitch|, |yaw| of VISION_POSITION_ESTIMATE
QUATERNION_NORM = (0.9, 1.1)  # ODOMETRY's q must be a rotation (normalised before use)
SYNC_WINDOW_S = 1.0  # a first stamp this close to the vehicle's time: the sender is on its clock
MAX_FUTURE_S = 0.1  # on the vehicle's clock: a stamp this far ahead is taken at arrival, beyond refused
MAX_AGE_S = 0.5  # on the vehicle's clock: an older sample is refused
RELEARN_AFTER = 5  # refused stamps in a row after which a sender's clock is decided again
MAX_SENDERS = 32  # senders whose clocks are remembered (the one heard from longest ago goes)
ANNOUNCE_EVERY_S = 10.0  # a refusal reason is announced at most this often (caller's clock)

ODOMETRY_FRAMES = {m.MAV_FRAME_LOCAL_NED: "LOCAL_NED", m.MAV_FRAME_LOCAL_FRD: "LOCAL_FRD"}
ODOMETRY_VELOCITY_FRAMES = (m.MAV_FRAME_BODY_FRD, *ODOMETRY_FRAMES)  # child_frame_id of the velocity
ODOMETRY_ESTIMATORS = (  # the types PX4 publishes as visual odometry (what EKF2 fuses)
    m.MAV_ESTIMATOR_TYPE_UNKNOWN, m.MAV_ESTIMATOR_TYPE_NAIVE, m.MAV_ESTIMATOR_TYPE_VISION,
    m.MAV_ESTIMATOR_TYPE_VIO,
)  # fmt: skip

# Refusal reasons (fixed words: they are counted and announced by them).
NO_EKF = "no estimator: the vehicle flies on the simulator's truth (EKF2_EN 0)"
EV_OFF = "EKF2_EV_CTRL is 0 (vision aiding off)"
NOT_FINITE = "a value is not finite"
TOO_FAR = f"a position farther than {MAX_DISTANCE_M:g} m"
BAD_ANGLE = "an angle beyond 2 pi"
BAD_QUATERNION = "q is not a rotation (norm far from 1)"
BAD_VARIANCE = "a variance that is negative or not finite"
BAD_FRAME = "ODOMETRY frame_id not LOCAL_NED or LOCAL_FRD"
MOCAP_ODOMETRY = (
    "ODOMETRY of estimator_type MOCAP: not for the EKF (as on PX4: send VISION_POSITION_ESTIMATE, "
    "or ODOMETRY of estimator_type VISION)"
)
OTHER_ESTIMATOR = "ODOMETRY estimator_type not UNKNOWN, NAIVE, VISION or VIO"
LOW_QUALITY = "ODOMETRY quality below EKF2_EV_QMIN"
FLOOD = "more than one sample per control frame"
FUTURE = "timestamp in the future of the vehicle's clock"
TOO_OLD = "timestamp too old"
OUT_OF_ORDER = "timestamp not later than the sender's previous one"
TOO_FAST = f"a velocity faster than {MAX_SPEED_M_S:g} m/s"
VELOCITY_FRAME = "ODOMETRY child_frame_id not BODY_FRD, LOCAL_NED or LOCAL_FRD: its velocity is not fused"

Sender = tuple  # (link index, address, system id, component id)


class Refused(ValueError):
    """A vision message that is not fused; ``str()`` is one of the reasons above."""


class _Clock(NamedTuple):
    on_vehicle_clock: bool
    last_stamp_usec: int
    refused_in_a_row: int
    heard_s: float  # the caller's clock, for eviction


class SenderClocks:
    """Each sender's clock, decided from its stamps (see the module's "Time")."""

    def __init__(self) -> None:
        self.clocks: dict[Sender, _Clock] = {}

    def sample_time(self, sender: Sender, stamp_usec: int, arrival_s: float, now: float) -> float:
        """When the sample stamped ``stamp_usec`` (the sender's clock) is valid, in simulation
        seconds; ``arrival_s``: the vehicle's time when it arrived; ``now``: the caller's clock.
        Refused (FUTURE, TOO_OLD, OUT_OF_ORDER) when it cannot be used."""
        if stamp_usec == 0:
            return arrival_s
        clock = self.clocks.get(sender)
        if clock is None or clock.refused_in_a_row >= RELEARN_AFTER:
            on_vehicle = abs(stamp_usec * 1e-6 - arrival_s) <= SYNC_WINDOW_S
            clock = _Clock(on_vehicle, -1, 0, now)
        elif stamp_usec <= clock.last_stamp_usec:
            self._keep(sender, clock._replace(refused_in_a_row=clock.refused_in_a_row + 1, heard_s=now))
            raise Refused(OUT_OF_ORDER)
        if not clock.on_vehicle_clock:
            self._keep(sender, clock._replace(last_stamp_usec=stamp_usec, heard_s=now))
            return arrival_s
        t = stamp_usec * 1e-6
        problem = FUTURE if t > arrival_s + MAX_FUTURE_S else TOO_OLD if t < arrival_s - MAX_AGE_S else None
        if problem is not None:
            self._keep(sender, clock._replace(refused_in_a_row=clock.refused_in_a_row + 1, heard_s=now))
            raise Refused(problem)
        self._keep(sender, _Clock(True, stamp_usec, 0, now))
        return min(t, arrival_s)

    def restart(self) -> None:
        """Forget every sender's clock (the simulation clock started again)."""
        self.clocks.clear()

    def _keep(self, sender: Sender, clock: _Clock) -> None:
        clocks = self.clocks
        if sender not in clocks and len(clocks) >= MAX_SENDERS:
            del clocks[min(clocks, key=lambda s: clocks[s].heard_s)]
        clocks[sender] = clock


def _std(variance: float) -> float:
    """A reported variance as a 1-sigma (0: unknown, the EKF2_*_NOISE floor alone)."""
    if not math.isfinite(variance) or variance < 0.0:
        raise Refused(BAD_VARIANCE)
    return math.sqrt(variance)


def _pose(position_ned, yaw_ned: float, covariance, read_covariance: bool) -> VisionPose:
    """The pose in the paper's frames, with the covariance's diagonal as 1-sigmas (time 0)."""
    if not all(math.isfinite(c) for c in (*position_ned, yaw_ned)):
        raise Refused(NOT_FINITE)
    if math.hypot(*position_ned) > MAX_DISTANCE_M:
        raise Refused(TOO_FAR)
    position_std = yaw_std = 0.0
    if read_covariance and len(covariance) == 21 and not math.isnan(covariance[0]):
        position_std = max(_std(covariance[0]), _std(covariance[6]), _std(covariance[11]))
        yaw_std = _std(covariance[20])
    return VisionPose(0.0, frames.vector_from_ned(position_ned), frames.wrap_pi(frames.yaw_from_ned(yaw_ned)),
                      position_std, yaw_std)  # fmt: skip


def read_vision_position_estimate(msg) -> tuple[int, VisionPose]:
    """``(usec, pose)`` of a VISION_POSITION_ESTIMATE; Refused with the reason."""
    angles = (msg.roll, msg.pitch, msg.yaw)
    if not all(math.isfinite(a) for a in angles):
        raise Refused(NOT_FINITE)
    if max(abs(a) for a in angles) > MAX_ANGLE_RAD:
        raise Refused(BAD_ANGLE)
    return msg.usec, _pose((msg.x, msg.y, msg.z), msg.yaw, msg.covariance, True)


def read_odometry(msg, quality_min: float) -> tuple[int, VisionPose]:
    """``(time_usec, pose)`` of an ODOMETRY; Refused with the reason."""
    if msg.estimator_type == m.MAV_ESTIMATOR_TYPE_MOCAP:
        raise Refused(MOCAP_ODOMETRY)
    if msg.estimator_type not in ODOMETRY_ESTIMATORS:
        raise Refused(OTHER_ESTIMATOR)
    if msg.frame_id not in ODOMETRY_FRAMES:
        raise Refused(BAD_FRAME)
    if msg.quality < quality_min:
        raise Refused(LOW_QUALITY)
    q = msg.q
    if not all(math.isfinite(c) for c in q):
        raise Refused(NOT_FINITE)
    norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if not QUATERNION_NORM[0] <= norm <= QUATERNION_NORM[1]:
        raise Refused(BAD_QUATERNION)
    w, x, y, z = (c / norm for c in q)
    yaw_ned = euler_from_quaternion(w, x, y, z)[2]  # ZYX yaw of body FRD in the NED (or FRD) frame
    naive = msg.estimator_type == m.MAV_ESTIMATOR_TYPE_NAIVE
    pose = _pose((msg.x, msg.y, msg.z), yaw_ned, msg.pose_covariance, not naive)
    velocity = (msg.vx, msg.vy, msg.vz)
    if not all(math.isfinite(v) for v in velocity) or msg.child_frame_id not in ODOMETRY_VELOCITY_FRAMES:
        return msg.time_usec, pose  # no velocity (the caller says so for a frame it cannot read)
    if math.hypot(*velocity) > MAX_SPEED_M_S:
        raise Refused(TOO_FAST)
    if msg.child_frame_id == m.MAV_FRAME_BODY_FRD:  # body FRD -> the pose's frame, by q
        velocity = matrix_times(rotation_from_quaternion(w, x, y, z), velocity)
    covariance = msg.velocity_covariance
    std = 0.0
    if not naive and len(covariance) == 21 and not math.isnan(covariance[0]):
        std = max(_std(covariance[0]), _std(covariance[6]), _std(covariance[11]))
    return msg.time_usec, pose._replace(velocity_m_s=frames.vector_from_ned(velocity), velocity_std_m_s=std)


class ExternalVision:
    """The edge for the clients' vision messages; :meth:`receive` gives the pose to fuse."""

    def __init__(self) -> None:
        self.clocks = SenderClocks()
        self.accepted = 0  # poses handed to the filter (its gates may still reject them)
        self.refused: Counter[str] = Counter()  # by reason (the fixed texts above)
        self.announcements: list[str] = []  # to send as STATUSTEXT (the caller takes them)
        self._last_arrival = -math.inf  # the vehicle's time of the last pose handed on
        self._announced: dict[str, float] = {}

    def receive(self, msg, sender: Sender, arrival_s: float, now: float, on_ekf: bool,
                values) -> VisionPose | None:  # fmt: skip
        """The pose in ``msg`` (VISION_POSITION_ESTIMATE or ODOMETRY) to fuse, valid at its
        ``time_s``, or None (refused: counted, announced). ``arrival_s``: the vehicle's time (the
        latest frame's); ``now``: the caller's clock (announcements); ``on_ekf``: the vehicle flies
        on its EKF; ``values``: the parameters (EKF2_EV_CTRL, EKF2_EV_QMIN)."""
        try:
            if not on_ekf:
                raise Refused(NO_EKF)
            ctrl = int(values["EKF2_EV_CTRL"])
            if ctrl == 0:
                raise Refused(EV_OFF)
            if msg.get_msgId() == m.MAVLINK_MSG_ID_ODOMETRY:
                stamp, pose = read_odometry(msg, values["EKF2_EV_QMIN"])
                velocity = math.isfinite(msg.vx) and math.isfinite(msg.vy) and math.isfinite(msg.vz)
                if velocity and msg.child_frame_id not in ODOMETRY_VELOCITY_FRAMES:
                    self._announce(VELOCITY_FRAME, now)
            else:
                stamp, pose = read_vision_position_estimate(msg)
            if arrival_s == self._last_arrival:
                raise Refused(FLOOD)
            t = self.clocks.sample_time(sender, stamp, arrival_s, now)
        except Refused as refused:
            self.refused[str(refused)] += 1
            self._announce(f"vision refused: {refused}", now)
            return None
        self._last_arrival = arrival_s
        self.accepted += 1
        return pose._replace(time_s=t)

    def restart(self) -> None:
        """The simulation clock started again (a restarted simulator): the senders' clocks are
        decided afresh; the counts stay."""
        self.clocks.restart()
        self._last_arrival = -math.inf

    def _announce(self, text: str, now: float) -> None:
        """Each text the first time, then at most every :data:`ANNOUNCE_EVERY_S` while it recurs
        (the counts are in the autopilot's info)."""
        last = self._announced.get(text)
        if last is None or now - last >= ANNOUNCE_EVERY_S:
            self._announced[text] = now
            self.announcements.append(text)

    def take_announcements(self) -> list[str]:
        """The STATUSTEXTs announced since the last call (why poses were refused), emptied."""
        texts, self.announcements = self.announcements, []
        return texts

    def info(self) -> dict:
        """The counters for ``quadsitl/<N>/autopilot/info``: poses accepted, refusals by reason."""
        return {"accepted": self.accepted, "refused": dict(self.refused)}
