"""Recorded sessions -> FlightRecord: what the analysis works on, from logs only.

Reads what :mod:`gcs_scripts.record` writes: a merged ``NAME.parquet``, or the
``NAME.parts/`` directory a recorder that died leaves behind (or a bare ``NAME``). Also accepts
the Parquet files of in-process runs (``FlightRecord.write_parquet``), so SITL and in-process
runs can be compared, and the autopilot's flight logs (``.ulg``: the same columns from its
``paper_tracking`` topic, :mod:`.ulog_reader`; no estimator columns there).

* position and Euler angles: the simulator's ground truth (``x_m``..., ``phi_rad``...);
* references, U1 and tau (Euler coordinates): the controller's own record (``x_ref_m``...,
  ``phi_ref_rad``..., ``U1_n``, ``tau_phi_n_m``...);
* disturbances: the truth's applied force/torque (``Ax_n``..., ``Ap_n_m``...); event times are
  the instants where the applied disturbance changes (the first sample of each change);
* the estimate (a session flown with ``--estimator ekf``): the estimator's columns
  (``x_est_m``...) as ``FlightRecord.estimator``, NaN where the filter had none.

Only rows with all of these are kept (on the ground before arming the controller publishes no
reference). A window ``(t0, duration)`` trims to ``[t0, t0 + duration]`` and shifts time so it
starts at 0: a trajectory flown through the SITL from simulation time t0 then lines up with an
in-process run of the same scenario, which starts at 0.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from gcs_scripts.session_log import read_session_table, resolve_session_path, time_key

from .record import ESTIMATOR_COLUMNS, FlightRecord
from .ulog_reader import is_ulog, read_ulog_columns

Window = tuple[
    float | None, float | None
]  # (t0 s or None = the first sample, duration s or None = to the end)

REQUIRED = (
    "x_m", "y_m", "z_m", "phi_rad", "theta_rad", "psi_rad",
    "x_ref_m", "y_ref_m", "z_ref_m", "phi_ref_rad", "theta_ref_rad", "psi_ref_rad",
    "U1_n", "tau_phi_n_m", "tau_theta_n_m", "tau_psi_n_m",
)  # fmt: skip
DISTURBANCE = ("Ax_n", "Ay_n", "Az_n", "Ap_n_m", "Aq_n_m", "Ar_n_m")
_WINDOW_EPS_S = 1e-6  # time stamps are on a µs grid


def coalesce_duplicate_times(cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Sort rows by time; rows sharing a time (µs) become one, each column its last non-NaN value.

    Duplicates happen when a stream resumed after being reported stale: the recorder then wrote
    the late side of a row in a later part.
    """
    keys = time_key(cols["time_s"])
    order = np.argsort(keys, kind="stable")
    keys = keys[order]
    cols = {name: np.asarray(v, dtype=float)[order] for name, v in cols.items()}
    if len(keys) < 2 or np.all(keys[1:] != keys[:-1]):
        return cols
    starts = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]])
    ends = np.r_[starts[1:], len(keys)]
    for s, e in zip(starts, ends, strict=True):
        if e - s > 1:  # rare: a Python loop over the duplicate groups only
            for v in cols.values():
                block = v[s:e]
                finite = block[~np.isnan(block)]
                v[s] = finite[-1] if len(finite) else np.nan
    return {name: v[starts] for name, v in cols.items()}


def disturbance_events(time_s: np.ndarray, disturbance: np.ndarray | None) -> list[float]:
    """Instants where the applied disturbance starts to change (first sample of each change).

    A step gives one instant; a ramp gives one instant (its start), not one per sample.
    """
    if disturbance is None or len(time_s) < 2:
        return []
    d = np.nan_to_num(np.asarray(disturbance, dtype=float))
    changed = np.any(d[1:] != d[:-1], axis=1)  # changed[k]: sample k+1 differs from sample k
    onset = changed & ~np.r_[False, changed[:-1]]
    return [float(t) for t in np.asarray(time_s)[1:][onset]]


def _window_mask(time_s: np.ndarray, window: Window | None) -> tuple[np.ndarray, float]:
    if window is None:
        return np.ones(len(time_s), dtype=bool), 0.0
    t0, duration = window
    if t0 is None:
        t0 = float(time_s[0]) if len(time_s) else 0.0
    end = math.inf if duration is None else t0 + duration
    return (time_s >= t0 - _WINDOW_EPS_S) & (time_s <= end + _WINDOW_EPS_S), float(t0)


def _is_flight_record_file(path: Path) -> bool:
    if path.is_dir() or path.suffix != ".parquet":
        return False
    meta = pq.read_schema(path).metadata or {}
    return b"quadsitl.flight_record" in meta


def read_session(
    path: str | Path,
    window: Window | None = None,
    label: str | None = None,
) -> FlightRecord:
    """A FlightRecord from a recorded session (file, parts directory or bare NAME).

    ``window = (t0, duration)`` (s of simulation time; None parts mean the first sample / the
    end) trims to ``[t0, t0 + duration]`` and shifts time so the window starts at 0. For an
    in-process FlightRecord file (which starts at 0 already) only the duration applies.
    Raises FileNotFoundError or ValueError with a message naming the file.
    """
    resolved = resolve_session_path(path)
    if _is_flight_record_file(resolved):
        return _read_flight_record(resolved, window, label)
    if is_ulog(resolved):
        columns, meta = read_ulog_columns(resolved)
        kind = "flight log"
    else:
        table, meta = read_session_table(resolved)
        columns = {c: table.column(c) for c in table.column_names}
        kind = "sitl log"
    missing = [c for c in ("time_s", *REQUIRED) if c not in columns]
    if missing:
        raise ValueError(f"{resolved}: not a quadsitl session log (missing columns {', '.join(missing)})")
    has_estimator = all(c in columns for c in ESTIMATOR_COLUMNS)
    estimator_cols = ESTIMATOR_COLUMNS if has_estimator else ()
    wanted = ["time_s", *REQUIRED, *(c for c in DISTURBANCE if c in columns), *estimator_cols]
    cols = coalesce_duplicate_times({c: as_array(columns[c]) for c in wanted})
    complete = np.all([~np.isnan(cols[c]) for c in REQUIRED], axis=0)
    in_window, t0 = _window_mask(cols["time_s"], window)
    keep = complete & in_window
    if keep.sum() < 2:
        times = cols["time_s"]
        span = f"t={times[0]:.3f}..{times[-1]:.3f} s" if len(times) else "no rows"
        where = "" if window is None else f" in the window from t0={t0:g} s, duration {window[1]} s"
        raise ValueError(
            f"{resolved}: fewer than 2 samples with truth and controller data{where} (log: {span})"
        )
    cols = {name: v[keep] for name, v in cols.items()}
    time_s = cols["time_s"] - (t0 if window is not None else 0.0)

    def stack(*names: str) -> np.ndarray:
        return np.column_stack([cols[n] for n in names])

    force = stack(*DISTURBANCE[:3]) if all(c in cols for c in DISTURBANCE[:3]) else None
    torque = stack(*DISTURBANCE[3:]) if all(c in cols for c in DISTURBANCE[3:]) else None
    both = None if force is None or torque is None else np.column_stack([force, torque])
    controller = meta.get("controller", "") or ""
    return FlightRecord(
        label=label or controller or resolved.stem,
        scenario=meta.get("scenario", "") or "",
        controller=controller,
        time_s=time_s,
        position_m=stack("x_m", "y_m", "z_m"),
        position_ref_m=stack("x_ref_m", "y_ref_m", "z_ref_m"),
        euler_rad=stack("phi_rad", "theta_rad", "psi_rad"),
        euler_ref_rad=stack("phi_ref_rad", "theta_ref_rad", "psi_ref_rad"),
        thrust_n=cols["U1_n"],
        torque_euler_n_m=stack("tau_phi_n_m", "tau_theta_n_m", "tau_psi_n_m"),
        disturbance_force_n=force,
        disturbance_torque_n_m=torque,
        event_times_s=disturbance_events(time_s, both),
        source=f"{kind} {resolved}" + ("" if window is None else f" from t0={t0:g} s"),
        estimator=np.column_stack([time_s, stack(*ESTIMATOR_COLUMNS)]) if has_estimator else None,
    )


def as_array(column) -> np.ndarray:
    """A column as a numpy array (pyarrow columns are converted; arrays pass through)."""
    return column if isinstance(column, np.ndarray) else column.to_numpy(zero_copy_only=False)


def _read_flight_record(path: Path, window: Window | None, label: str | None) -> FlightRecord:
    """An in-process run's file; a window applies as for SITL logs (its t0 defaults to 0)."""
    record = FlightRecord.read_parquet(path)
    if label:
        record.label = label
    if window is None or (window[0] is None and window[1] is None):
        return record
    t0 = 0.0 if window[0] is None else window[0]
    end = float(record.time_s[-1]) if window[1] is None else t0 + window[1]
    trimmed = record.window(t0, end, shift=True)
    if len(trimmed.time_s) == 0:
        raise ValueError(
            f"{path}: no samples in the window t0={t0:g} s, duration {window[1]} s "
            f"(the run covers {record.time_s[0]:g}..{record.time_s[-1]:g} s)"
        )
    return trimmed
