"""From the zenoh rows of one vehicle to the view's samples: decimation, join, disturbance onsets.

Pure: decoded row arrays in (:mod:`quadcommon.bus_records` layouts), small records out.

The simulator publishes one truth row per control frame (500 Hz of simulation time, 6 000 rows
per wall second at ``--speed max``); the page needs at most 30 samples per wall second. Every
row is still looked at for one thing: the instants where the applied disturbance starts to change
(the same rule as :func:`gcs_scripts.analysis.log_reader.disturbance_events`, kept across
batches), so a gust step between two samples is still marked at its exact time.

A sample joins the truth and controller rows of the latest control step both streams have
reached (exact on the microsecond key, as the recorder joins them): the two come from different
processes in batches of 10 rows, and at 1 m/s a 20 ms mismatch would show as a 20 mm error
where the paper's controller holds a millimetre.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from quadcommon.bus_records import CONTROLLER_FIELDS, TRUTH_FIELDS

_T = {name: i for i, name in enumerate(TRUTH_FIELDS)}
_C = {name: i for i, name in enumerate(CONTROLLER_FIELDS)}
DISTURBANCE_COLUMNS = [_T[n] for n in ("Ax_n", "Ay_n", "Az_n", "Ap_n_m", "Aq_n_m", "Ar_n_m")]
ROTOR_HEALTH_COLUMNS = [_T[f"rotor{n}_{what}"] for what in ("effectiveness", "failure") for n in (1, 2, 3, 4)]
CONTROLLER_STALE_S = 0.25  # controller rows older than this (sim s): show the truth without references
KEEP_ROWS = 256  # recent rows of each stream kept to find their latest common step (0.5 s at 500 Hz)


def _key(time_s: float | np.ndarray) -> np.ndarray:
    return np.rint(np.asarray(time_s, dtype=float) * 1e6).astype(np.int64)


def _clean(values: np.ndarray | list[float], digits: int) -> list[float | None]:
    """Rounded floats for JSON; NaN and infinities become None (JSON has no NaN)."""
    return [round(float(v), digits) if math.isfinite(v) else None for v in values]


@dataclass
class Sample:
    """One decimated state of a vehicle (paper frames, SI units; None = unknown)."""

    time_s: float
    position_m: list[float | None]
    euler_rad: list[float | None]
    quaternion: list[float | None]  # body to world (w, x, y, z)
    position_ref_m: list[float | None]
    euler_ref_rad: list[float | None]
    thrust_n: float | None  # U1 as the controller applied it
    torque_euler_n_m: list[float | None]
    disturbance_force_n: list[float | None]  # world, at the CoM
    disturbance_torque_n_m: list[float | None]  # on the Euler coordinates
    on_ground: bool
    # rotors 1-4 (1 front, 2 right, 3 rear, 4 left): effectiveness, then FAILURE_TYPE (0 healthy)
    rotor_health: list[float | None] = dataclasses.field(default_factory=lambda: [1.0] * 4 + [0.0] * 4)

    def to_json(self) -> dict:
        """The sample as the page's compact JSON (short keys; world frame, SI: positions m, angles rad,
        thrust N, torques N m)."""
        return {
            "t": round(self.time_s, 6),
            "p": self.position_m,
            "eta": self.euler_rad,
            "q": self.quaternion,
            "pr": self.position_ref_m,
            "etar": self.euler_ref_rad,
            "u1": self.thrust_n,
            "tau": self.torque_euler_n_m,
            "df": self.disturbance_force_n,
            "dm": self.disturbance_torque_n_m,
            "ground": self.on_ground,
            "rot": self.rotor_health,
        }


class DisturbanceOnsets:
    """Instants where the applied disturbance starts to change, over a stream of row batches."""

    def __init__(self) -> None:
        self._last: np.ndarray | None = None
        self._changing = False

    def add(self, time_s: np.ndarray, disturbance: np.ndarray) -> list[float]:
        """Take a batch of rows (times s, disturbance values); return the onsets found in it (s)."""
        d = np.nan_to_num(np.asarray(disturbance, dtype=float))
        if len(d) == 0:
            return []
        if self._last is None:
            self._last = d[0]
            time_s, d = time_s[1:], d[1:]
            if len(d) == 0:
                return []
        if not self._changing and (d == self._last).all():
            return []  # the usual batch: the disturbance held constant throughout
        both = np.vstack([self._last[None, :], d])
        changed = np.any(both[1:] != both[:-1], axis=1)  # changed[k]: row k differs from the one before
        before = np.r_[self._changing, changed[:-1]]
        onset = changed & ~before
        self._last = d[-1]
        self._changing = bool(changed[-1])
        return [float(t) for t in np.asarray(time_s)[onset]]


class VehicleSampler:
    """Collects the truth and controller rows of one vehicle; :meth:`take` gives the latest sample."""

    def __init__(self) -> None:
        self._truth = np.empty((0, len(TRUTH_FIELDS)))
        self._controller = np.empty((0, len(CONTROLLER_FIELDS)))
        # Batches received since the last take(): joined once per tick, not once per batch (the
        # per-call overhead of numpy, not the arithmetic, is what costs here).
        self._pending_truth: list[np.ndarray] = []
        self._pending_controller: list[np.ndarray] = []
        self._new = False
        self._last_key: int | None = None
        self.onsets = DisturbanceOnsets()
        self.new_events: list[float] = []
        self.truth_rows = 0
        self.controller_rows = 0

    def add_truth(self, rows: np.ndarray) -> None:
        """Queue a batch of truth rows (time first) for the next merge."""
        if len(rows):
            self._pending_truth.append(rows)

    def add_controller(self, rows: np.ndarray) -> None:
        """Queue a batch of controller rows (time first) for the next merge."""
        if len(rows):
            self._pending_controller.append(rows)

    def _merge(self) -> None:
        if self._pending_truth:
            rows = np.concatenate(self._pending_truth)
            self._pending_truth = []
            self.truth_rows += len(rows)
            self.new_events.extend(self.onsets.add(rows[:, 0], rows[:, DISTURBANCE_COLUMNS]))
            self._truth = np.concatenate([self._truth, rows[-KEEP_ROWS:]])[-KEEP_ROWS:]
            self._new = True
        if self._pending_controller:
            rows = np.concatenate(self._pending_controller)
            self._pending_controller = []
            self.controller_rows += len(rows)
            self._controller = np.concatenate([self._controller, rows[-KEEP_ROWS:]])[-KEEP_ROWS:]
            self._new = True

    @property
    def latest_time_s(self) -> float | None:
        """The latest truth time received (s), or None."""
        if self._pending_truth:
            return float(self._pending_truth[-1][-1, 0])
        return float(self._truth[-1, 0]) if len(self._truth) else None

    def take_events(self) -> list[float]:
        """The disturbance onsets (s) found since the last call."""
        self._merge()
        out, self.new_events = self.new_events, []
        return out

    def take(self) -> Sample | None:
        """The newest sample since the last call (None if no new row arrived).

        It is the latest control step both streams have reached, once; when the controller's rows
        are missing or more than CONTROLLER_STALE_S behind (autopilot stopped), the latest truth
        row with unknown references, so the vehicle never freezes on the page.
        """
        self._merge()
        if not self._new or len(self._truth) == 0:
            return None
        self._new = False
        truth, ref = self._truth[-1], None
        if len(self._controller):
            common, i_truth, i_ctrl = np.intersect1d(
                _key(self._truth[:, 0]), _key(self._controller[:, 0]), return_indices=True
            )
            if len(common) and truth[0] - self._truth[i_truth[-1], 0] <= CONTROLLER_STALE_S:
                truth, ref = self._truth[i_truth[-1]], self._controller[i_ctrl[-1]]
        key = int(_key(truth[0]))
        if key == self._last_key:
            return None  # that step was sent already (the other stream has not caught up yet)
        self._last_key = key
        if ref is None:
            nan3 = [math.nan] * 3
            p_ref, eta_ref, u1, tau = nan3, nan3, math.nan, nan3
        else:
            p_ref = ref[[_C["x_ref_m"], _C["y_ref_m"], _C["z_ref_m"]]]
            eta_ref = ref[[_C["phi_ref_rad"], _C["theta_ref_rad"], _C["psi_ref_rad"]]]
            u1 = ref[_C["U1_n"]]
            tau = ref[[_C["tau_phi_n_m"], _C["tau_theta_n_m"], _C["tau_psi_n_m"]]]
        t = _T
        return Sample(
            time_s=float(truth[0]),
            position_m=_clean(truth[[t["x_m"], t["y_m"], t["z_m"]]], 6),
            euler_rad=_clean(truth[[t["phi_rad"], t["theta_rad"], t["psi_rad"]]], 6),
            quaternion=_clean(truth[[t["qw"], t["qx"], t["qy"], t["qz"]]], 6),
            position_ref_m=_clean(p_ref, 6),
            euler_ref_rad=_clean(eta_ref, 6),
            thrust_n=_clean([u1], 5)[0],
            torque_euler_n_m=_clean(tau, 6),
            disturbance_force_n=_clean(truth[[t["Ax_n"], t["Ay_n"], t["Az_n"]]], 5),
            disturbance_torque_n_m=_clean(truth[[t["Ap_n_m"], t["Aq_n_m"], t["Ar_n_m"]]], 5),
            on_ground=bool(truth[t["on_ground"]] > 0.5),
            rotor_health=_clean(truth[ROTOR_HEALTH_COLUMNS], 4),
        )
