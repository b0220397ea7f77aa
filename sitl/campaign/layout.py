"""Where each number sits in the flat float64 arrays the batch kernels take (numba wants arrays).

One module, imported by the kernels (as compile-time constants) and by the packer
(:mod:`sitl.campaign.engine`), so the two sides cannot disagree on an index.
"""

from __future__ import annotations

# -- plant (the true vehicle; read off a simulator.dynamics.plant.Plant instance) ------------------
P_MASS = 0
P_GRAVITY = 1
P_J = 2  # 9 entries, inertia tensor about G, row-major
P_K = 11  # 9 entries, its inverse (Plant.inertia_inv)
P_COM = 20  # 3: r_G, CoM from O in the body frame
P_DRAG = 23  # 3: linear drag per world axis
P_B = 26  # thrust coefficient b
P_D = 27  # reaction-torque coefficient d
P_ARM = 28
P_JR = 29  # rotor inertia
P_TAU = 30  # rotor time constant
P_WMIN = 31  # rotor speed limits
P_WMAX = 32
P_THRUST_MAX = 33
P_TORQUE_MAX = 34  # 3
P_ROTOR_MODE = 37  # 1.0 when actuation = "rotors"
P_GROUND = 38  # 1.0 when ground contact is on
P_HAS_DRAG = 39
P_SIZE = 40

# -- controller (read off an autopilot.control.cascade.Cascade instance) ---------------------------
C_TLAW = 0  # 0 integral_second_step, 1 integral_first_step, 2 backstepping
C_RLAW = 1  # 0 nlhinf, 1 integral_backstepping
C_MASS = 2  # nominal mass
C_GRAVITY = 3
C_THRUST_MAX = 4
C_THRUST_FLOOR = 5
C_SIN_TILT = 6
C_C1 = 7  # 3
C_C2 = 10  # 3
C_KI = 13  # 3
C_ONE_C1C2 = 16  # 3: 1 + c1 c2
C_C1_C2 = 19  # 3: c1 + c2
C_KD = 22  # NLHinf k_d
C_KP = 23  # NLHinf k_p
C_RINV = 24  # NLHinf 1 / omega_u^2
C_AC1 = 25  # 3: IntBS attitude c1
C_AC2 = 28  # 3
C_ALAM = 31  # 3
C_INERTIA = 34  # 3: nominal Ixx, Iyy, Izz
C_WN2 = 37  # command filter
C_2ZW = 38
C_PHI = 39  # 6: a00, a01, a02, a10, a11, a12
C_AB = 45  # allocator b, d, arm
C_AD = 46
C_AARM = 47
C_SQMIN = 48
C_SQMAX = 49
C_SPEED_MAX = 50
C_ATHRUST_MAX = 51
C_ATORQUE_MAX = 52  # 3
C_ROTOR_MODE = 55
C_DT = 56
C_SIZE = 57

TLAW_SECOND_STEP, TLAW_FIRST_STEP, TLAW_BACKSTEPPING = 0, 1, 2
RLAW_NLHINF, RLAW_INTBS = 0, 1

# -- simulation ----------------------------------------------------------------------------------
S_DT_CONTROL = 0
S_DT_PHYSICS = 1
S_SUBSTEPS = 2
S_STEPS = 3  # control steps; samples k = 0..steps
S_WIRE = 4  # 1.0: float32 state and controls as on the MAVLink wire
S_USEC_PER_FRAME = 5  # informational: the reference table is sampled on this clock
S_MAX_POS_ERR = 6
S_MAX_TILT = 7
S_AIRBORNE = 8  # height of O above which the vehicle counts as airborne
S_DRYDEN_ON = 9
S_DRYDEN_T0 = 10  # start_time + dryden.start_s (s)
S_DRYDEN_FROM = 11  # profile time window of the turbulence
S_DRYDEN_UNTIL = 12
S_DRYDEN_STEP = 13
S_SIZE = 14

# -- metrics (one row per run, see engine.METRIC_NAMES) -------------------------------------------
M_FINAL = 0  # 3: final position error x, y, z
M_ISE = 3  # 6: x, y, z, phi, theta, psi
M_IADU = 9  # 4: U1, tau_phi, tau_theta, tau_psi
M_MAX_POS_ERR = 13
M_MAX_TILT = 14
M_T_SAT = 15  # time with an actuator limit active (s)
M_T_TILT = 16  # time with the roll/pitch reference at the tilt limit (s)
M_FAIL = 17  # failure code (FAIL_*)
M_T_FAIL = 18  # time of the failure (s), NaN when none
M_T_END = 19  # last sample's time (s)
M_SIZE = 20

FAIL_NONE, FAIL_NONFINITE, FAIL_POSITION, FAIL_TILT, FAIL_GROUND = 0, 1, 2, 3, 4

# -- recorded time series (run_scenario's columns, one row per control step) ----------------------
RECORD_COLUMNS = (
    "t", "x", "y", "z", "xd", "yd", "zd", "phi", "theta", "psi", "phid", "thetad", "psid",
    "U1", "tau_phi", "tau_theta", "tau_psi", "Ax", "Ay", "Az", "Ap", "Aq", "Ar",
)  # fmt: skip
R_SIZE = len(RECORD_COLUMNS)
