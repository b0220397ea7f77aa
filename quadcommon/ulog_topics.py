"""The flight log's own topics: their names and field layouts, the format the autopilot writes
and the ground stations read.

Written once here because both sides read it: the autopilot's logger
(:mod:`autopilot.logger.topics` builds their samples) and the ground stations' log reader
(:mod:`gcs_scripts.analysis.ulog_reader`) meet on this format as they meet on the wire
(:mod:`quadcommon.wire`). Layouts are ULog format strings (``type name`` pairs joined by ``;``);
frames are the paper's (world x north / y west / z up, body front-left-up, ZYX Euler), SI units.
"""

from __future__ import annotations

__all__ = [
    "CASCADE", "CASCADE_FIELDS", "DISTURBANCE", "DISTURBANCE_FIELDS", "ROTORS", "ROTORS_FIELDS",
    "TRACKING", "TRACKING_FIELDS",
]  # fmt: skip

# Every control step: the truth the HIL frame carries, the reference, eta_d, U1 (N), tau_eta (N m).
TRACKING = "paper_tracking"
TRACKING_FIELDS = (
    "float[3] position_m; float[3] position_ref_m; float[3] euler_rad; float[3] euler_ref_rad; "
    "float thrust_n; float[3] torque_euler_n_m; uint32_t custom_mode; bool armed"
)

# The rest of the cascade (the logger appends the laws' integral states, one field per state).
CASCADE = "cascade_status"
CASCADE_FIELDS = (
    "float[3] velocity_ref_m_s; float[3] acceleration_ref_m_s2; float[2] roll_pitch_raw_rad; "
    "float[3] euler_rate_ref_rad_s; float[3] acceleration_cmd_m_s2; float[3] torque_body_n_m; "
    "float[4] actuator_controls; float[4] rotor_speeds_rad_s"
)

# The disturbance the simulator applies: force at the CoM (world, N), torque on the Euler coordinates (N m).
DISTURBANCE = "sim_disturbance"
DISTURBANCE_FIELDS = "float[3] force_n; float[3] torque_n_m"

# The rotors' health the simulator applies: effectiveness (1 healthy, 0 off) and FAILURE_TYPE, rotors 1-4.
ROTORS = "sim_rotors"
ROTORS_FIELDS = "float[4] effectiveness; uint8_t[4] failure_type"
