"""The autopilot's flight logs (ULog, ``.ulg``) as the columns of a recorded session, read by pyulog.

``quadsitl analyze`` and ``quadsitl view`` read a ``.ulg`` as they read the recorder's Parquet:
this module gives the same column names (:mod:`gcs_scripts.analysis.log_reader`), from the
log's own topics (:mod:`quadcommon.ulog_topics`), in the paper's frames:

* ``time_s`` and, one row per control step, ``x_m`` ... (the truth the HIL frame carried),
  ``x_ref_m`` ..., ``phi_rad`` ..., ``phi_ref_rad`` ..., ``U1_n``, ``tau_phi_n_m`` ...,
  ``armed``, ``custom_mode``: the ``paper_tracking`` topic, float32 in the file;
* ``Ax_n`` ... ``Ar_n_m``: the ``sim_disturbance`` topic (when the log has it) as of each row:
  its latest sample at or before the row's time (it is logged at every onset, so the events
  the analysis finds are where they were);
* ``rotor1_effectiveness`` ... ``rotor4_failure``: the ``sim_rotors`` topic (when the log has it) as
  of each row, the rotors' health as the truth rows carry it;
* ``mav_landed_state``: MAV_LANDED_STATE from ``vehicle_land_detected`` as of each row (1 on the
  ground, 4 landing, 2 in the air; a takeoff reads as in the air).

The metadata: the controller and vehicle the autopilot flew (info messages), the source, and
every logged string (the vehicle's STATUSTEXT) as ``statustext`` ``[t, severity, text]``.

Against the recorder's Parquet of the same flight: the truth there is the simulator's (float64),
here the HIL frame's (ODOMETRY, float32), and every value went through float32 once more; so
the paper's indices agree to float32 quantisation (docs/logs.md gives the tolerance measured).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from quadcommon.ulog_topics import DISTURBANCE, ROTORS, TRACKING

# paper_tracking's fields -> the session columns (log_reader.REQUIRED and the status columns)
TRACKING_COLUMNS = {
    "position_m[0]": "x_m", "position_m[1]": "y_m", "position_m[2]": "z_m",
    "position_ref_m[0]": "x_ref_m", "position_ref_m[1]": "y_ref_m", "position_ref_m[2]": "z_ref_m",
    "euler_rad[0]": "phi_rad", "euler_rad[1]": "theta_rad", "euler_rad[2]": "psi_rad",
    "euler_ref_rad[0]": "phi_ref_rad", "euler_ref_rad[1]": "theta_ref_rad", "euler_ref_rad[2]": "psi_ref_rad",
    "thrust_n": "U1_n",
    "torque_euler_n_m[0]": "tau_phi_n_m", "torque_euler_n_m[1]": "tau_theta_n_m",
    "torque_euler_n_m[2]": "tau_psi_n_m",
    "armed": "armed", "custom_mode": "custom_mode",
}  # fmt: skip
DISTURBANCE_COLUMNS = {
    "force_n[0]": "Ax_n", "force_n[1]": "Ay_n", "force_n[2]": "Az_n",
    "torque_n_m[0]": "Ap_n_m", "torque_n_m[1]": "Aq_n_m", "torque_n_m[2]": "Ar_n_m",
}  # fmt: skip
ROTOR_COLUMNS = {
    **{f"effectiveness[{i}]": f"rotor{i + 1}_effectiveness" for i in range(4)},
    **{f"failure_type[{i}]": f"rotor{i + 1}_failure" for i in range(4)},
}
LANDED_ON_GROUND, LANDED_IN_AIR, LANDED_LANDING = 1, 2, 4


def is_ulog(path: str | Path) -> bool:
    """Whether ``path`` names a PX4 flight log (suffix ``.ulg``, any case)."""
    return Path(path).suffix.lower() == ".ulg"


def _as_of(times: np.ndarray, sample_times: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``values`` (sampled at ``sample_times``) at each of ``times``: the latest sample at or
    before it, NaN before the first."""
    index = np.searchsorted(sample_times, times, side="right") - 1
    out = np.where(index >= 0, values[np.clip(index, 0, None)], np.nan)
    return out.astype(float)


def read_ulog_columns(path: str | Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The session columns and metadata of a flight log; FileNotFoundError, or ValueError naming
    the file when it is not a quadsitl flight log (no ``paper_tracking`` topic) or not a ULog."""
    from pyulog import ULog
    from pyulog.core import ULogException

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"no flight log at {p}")
    try:
        ulog = ULog(str(p), [TRACKING, DISTURBANCE, ROTORS, "vehicle_land_detected"],
                    disable_str_exceptions=True)  # fmt: skip
    except (ULogException, ValueError, IndexError, KeyError) as exc:  # pyulog's own and its parser's
        raise ValueError(f"{p}: not a readable ULog ({exc})") from exc
    data = {d.name: d.data for d in ulog.data_list if d.multi_id == 0}
    tracking = data.get(TRACKING)
    if tracking is None:
        raise ValueError(f"{p}: not a quadsitl flight log (no {TRACKING} topic)")
    t_us = tracking["timestamp"].astype(np.int64)
    cols: dict[str, np.ndarray] = {"time_s": t_us * 1e-6}
    for field, column in TRACKING_COLUMNS.items():
        cols[column] = tracking[field].astype(float)
    for topic, fields in ((DISTURBANCE, DISTURBANCE_COLUMNS), (ROTORS, ROTOR_COLUMNS)):
        held = data.get(topic)
        if held is not None and len(held["timestamp"]):
            order = np.argsort(held["timestamp"], kind="stable")
            times = held["timestamp"][order].astype(np.int64)
            for field, column in fields.items():
                cols[column] = _as_of(t_us, times, held[field][order].astype(float))
    land = data.get("vehicle_land_detected")
    if land is not None and len(land["timestamp"]):
        state = np.where(land["landed"] > 0, LANDED_ON_GROUND,
                         np.where(land["in_descend"] > 0, LANDED_LANDING, LANDED_IN_AIR))  # fmt: skip
        cols["mav_landed_state"] = _as_of(t_us, land["timestamp"].astype(np.int64), state.astype(float))
    info = ulog.msg_info_dict
    meta = {
        "controller": info.get("quadsitl_controller", ""),
        "vehicle": info.get("quadsitl_vehicle", ""),
        "scenario": "",
        "source": f"flight log {p}",
        "statustext": [
            [m.timestamp * 1e-6, m.log_level - ord("0"), m.message] for m in ulog.logged_messages
        ],
    }
    return cols, meta
