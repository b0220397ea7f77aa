"""FlightRecord: the time series every analysis works on, whatever produced it.

The in-process runner fills one directly; the log reader (``quadsitl analyze``) builds one from
a recorded Parquet log. Paper frames, SI units; errors are actual - desired.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from quadcommon.bus_records import ESTIMATOR_FIELDS

ESTIMATOR_COLUMNS = ESTIMATOR_FIELDS[1:]  # the estimator's columns in a Parquet file (time_s is shared)


@dataclass
class FlightRecord:
    label: str  # e.g. the controller name
    scenario: str
    controller: str
    time_s: np.ndarray  # (N,)
    position_m: np.ndarray  # (N, 3) x, y, z of O, world (z up)
    position_ref_m: np.ndarray  # (N, 3)
    euler_rad: np.ndarray  # (N, 3) phi, theta, psi
    euler_ref_rad: np.ndarray  # (N, 3) phi_d, theta_d (filtered), psi_d
    thrust_n: np.ndarray  # (N,) U1 applied
    torque_euler_n_m: np.ndarray  # (N, 3) tau_phi, tau_theta, tau_psi applied
    disturbance_force_n: np.ndarray | None = None  # (N, 3) world
    disturbance_torque_n_m: np.ndarray | None = None  # (N, 3) on Euler coordinates
    event_times_s: list[float] = field(default_factory=list)
    source: str = "in-process"
    # Flown on the EKF: its rows (N, len(ESTIMATOR_FIELDS)), NaN before it had an estimate.
    estimator: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.time_s)
        for name in (
            "position_m",
            "position_ref_m",
            "euler_rad",
            "euler_ref_rad",
            "torque_euler_n_m",
        ):
            value = getattr(self, name)
            if value.shape != (n, 3):
                raise ValueError(f"FlightRecord.{name} has shape {value.shape}, expected ({n}, 3)")
        if self.thrust_n.shape != (n,):
            raise ValueError(f"FlightRecord.thrust_n has shape {self.thrust_n.shape}, expected ({n},)")
        if self.estimator is not None and self.estimator.shape != (n, len(ESTIMATOR_FIELDS)):
            raise ValueError(
                f"FlightRecord.estimator has shape {self.estimator.shape}, "
                f"expected ({n}, {len(ESTIMATOR_FIELDS)})"
            )

    @property
    def position_error_m(self) -> np.ndarray:
        """Position minus reference, (N, 3), world frame (m)."""
        return self.position_m - self.position_ref_m

    @property
    def euler_error_rad(self) -> np.ndarray:
        """Euler angles minus reference, (N, 3), wrapped to [-pi, pi) (rad)."""
        err = self.euler_rad - self.euler_ref_rad
        return (err + np.pi) % (2.0 * np.pi) - np.pi

    @property
    def controls(self) -> np.ndarray:
        """(N, 4): U1, tau_phi, tau_theta, tau_psi."""
        return np.column_stack([self.thrust_n, self.torque_euler_n_m])

    def window(self, start_s: float, end_s: float, shift: bool = False) -> FlightRecord:
        """The samples with ``start_s <= t <= end_s`` (µs tolerance); ``shift`` makes time start at 0."""
        keep = (self.time_s >= start_s - 1e-6) & (self.time_s <= end_s + 1e-6)
        cols = {name: np.asarray(v)[keep] for name, v in self.to_columns().items()}
        offset = start_s if shift else 0.0
        cols["time_s"] = cols["time_s"] - offset
        meta = {
            "label": self.label,
            "scenario": self.scenario,
            "controller": self.controller,
            "event_times_s": [t - offset for t in self.event_times_s if start_s <= t <= end_s],
            "source": self.source,
        }
        return FlightRecord.from_columns(cols, meta)

    # -- Parquet --------------------------------------------------------------------------------
    def to_columns(self) -> dict[str, np.ndarray]:
        """Flat named columns (the names the SITL log uses for the same quantities)."""
        cols = {"time_s": self.time_s}
        for i, axis in enumerate(("x", "y", "z")):
            cols[f"{axis}_m"] = self.position_m[:, i]
            cols[f"{axis}_ref_m"] = self.position_ref_m[:, i]
        for i, angle in enumerate(("phi", "theta", "psi")):
            cols[f"{angle}_rad"] = self.euler_rad[:, i]
            cols[f"{angle}_ref_rad"] = self.euler_ref_rad[:, i]
        cols["U1_n"] = self.thrust_n
        for i, name in enumerate(("tau_phi", "tau_theta", "tau_psi")):
            cols[f"{name}_n_m"] = self.torque_euler_n_m[:, i]
        if self.disturbance_force_n is not None:
            for i, name in enumerate(("Ax", "Ay", "Az")):
                cols[f"{name}_n"] = self.disturbance_force_n[:, i]
        if self.disturbance_torque_n_m is not None:
            for i, name in enumerate(("Ap", "Aq", "Ar")):
                cols[f"{name}_n_m"] = self.disturbance_torque_n_m[:, i]
        if self.estimator is not None:  # flown on truth: no estimator columns at all
            for i, name in enumerate(ESTIMATOR_COLUMNS, start=1):
                cols[name] = self.estimator[:, i]
        return cols

    def write_parquet(self, path) -> Path:
        """Write the record's columns (:meth:`to_columns`) to a Parquet file at ``path``, with the label,
        scenario, controller and event times as JSON metadata; return the path."""
        import json

        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.table(self.to_columns())
        meta = {
            "label": self.label,
            "scenario": self.scenario,
            "controller": self.controller,
            "event_times_s": self.event_times_s,
            "source": self.source,
        }
        table = table.replace_schema_metadata({"quadsitl.flight_record": json.dumps(meta)})
        path = Path(path)
        pq.write_table(table, path)
        return path

    @classmethod
    def from_columns(cls, cols, meta: dict) -> FlightRecord:
        def stack(*names):
            return np.column_stack([np.asarray(cols[n], dtype=float) for n in names])

        def optional(*names):
            return stack(*names) if all(n in cols for n in names) else None

        estimator = optional(*ESTIMATOR_COLUMNS)
        if estimator is not None:  # its time is the record's (one estimator row per frame)
            estimator = np.column_stack([np.asarray(cols["time_s"], dtype=float), estimator])

        return cls(
            label=meta.get("label", meta.get("controller", "")),
            scenario=meta.get("scenario", ""),
            controller=meta.get("controller", ""),
            time_s=np.asarray(cols["time_s"], dtype=float),
            position_m=stack("x_m", "y_m", "z_m"),
            position_ref_m=stack("x_ref_m", "y_ref_m", "z_ref_m"),
            euler_rad=stack("phi_rad", "theta_rad", "psi_rad"),
            euler_ref_rad=stack("phi_ref_rad", "theta_ref_rad", "psi_ref_rad"),
            thrust_n=np.asarray(cols["U1_n"], dtype=float),
            torque_euler_n_m=stack("tau_phi_n_m", "tau_theta_n_m", "tau_psi_n_m"),
            disturbance_force_n=optional("Ax_n", "Ay_n", "Az_n"),
            disturbance_torque_n_m=optional("Ap_n_m", "Aq_n_m", "Ar_n_m"),
            event_times_s=list(meta.get("event_times_s", [])),
            source=meta.get("source", ""),
            estimator=estimator,
        )

    @classmethod
    def read_parquet(cls, path) -> FlightRecord:
        import json

        import pyarrow.parquet as pq

        table = pq.read_table(path)
        raw = (table.schema.metadata or {}).get(b"quadsitl.flight_record", b"{}")
        cols = {name: table.column(name).to_numpy() for name in table.column_names}
        return cls.from_columns(cols, json.loads(raw))
