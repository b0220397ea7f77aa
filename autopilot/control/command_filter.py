"""Second-order command filter: eta_d, eta_d', eta_d'' from the stepwise roll/pitch references.

The inner loop needs the first two derivatives of the roll/pitch references the outer loop
produces (CONTROL.md). Each channel is ``y'' = wn^2 (r - y) - 2 zeta wn y'``, discretised exactly
for a reference held over the control step (zero-order hold), so it is stable at any rate. A
controller may also pass the references through unfiltered (``enabled = false``: its attitude
law then gets zero reference rates and accelerations, as PX4's attitude controller does).

:func:`discretise` computes the exact discretisation once (scipy's matrix exponential);
:func:`advance` is the per-step kernel over the cascade's numbers (layout ``F_*`` of the
coefficients inside the cascade's array, ``S_*`` of the filter's state).
"""

from __future__ import annotations

from quadcommon.kernel import kernel

# Coefficients, from an offset into the cascade's array: on/off, wn^2, 2 zeta wn, the first two rows
# of the discrete transition (a00, a01, a02, a10, a11, a12) of [y, y', r].
F_ON, F_WN2, F_2ZW, F_PHI = 0, 1, 2, 3
F_SIZE = 9
# State: y (roll, pitch), y' (roll, pitch), initialised (1.0 / 0.0).
S_Y, S_YD, S_READY = 0, 2, 4
S_SIZE = 5


def discretise(
    natural_frequency_rad_s: float, damping: float, dt: float, enabled: bool = True
) -> tuple[float, ...]:
    """The filter's coefficients (layout ``F_*``) for the control period ``dt``."""
    import numpy as np
    from scipy.linalg import expm  # here: importing scipy.linalg costs every process start ~0.2 s

    wn2 = natural_frequency_rad_s**2
    two_zeta_wn = 2.0 * damping * natural_frequency_rad_s
    # Augmented continuous system [y, y', r]' with r constant over the step.
    A = np.array([[0.0, 1.0, 0.0], [-wn2, -two_zeta_wn, wn2], [0.0, 0.0, 0.0]])
    phi = expm(A * dt)[:2].ravel()
    return (1.0 if enabled else 0.0, wn2, two_zeta_wn, *(float(v) for v in phi))


@kernel
def advance(f, offset, state, roll_ref, pitch_ref):
    """``(phi_d, theta_d, phi_d', theta_d', phi_d'', theta_d'')`` now, for the references held over
    the next step, then the state advanced by one step. The first step starts at the references,
    at rest."""
    if f[offset + F_ON] == 0.0:
        return roll_ref, pitch_ref, 0.0, 0.0, 0.0, 0.0
    if state[S_READY] == 0.0:
        state[S_Y], state[S_Y + 1] = roll_ref, pitch_ref
        state[S_YD], state[S_YD + 1] = 0.0, 0.0
        state[S_READY] = 1.0
    phi_d, theta_d = state[S_Y], state[S_Y + 1]
    phi_dd, theta_dd = state[S_YD], state[S_YD + 1]
    wn2, two_zeta_wn = f[offset + F_WN2], f[offset + F_2ZW]
    phi_ddd = wn2 * (roll_ref - phi_d) - two_zeta_wn * phi_dd
    theta_ddd = wn2 * (pitch_ref - theta_d) - two_zeta_wn * theta_dd
    a = offset + F_PHI
    state[S_Y] = f[a] * phi_d + f[a + 1] * phi_dd + f[a + 2] * roll_ref
    state[S_YD] = f[a + 3] * phi_d + f[a + 4] * phi_dd + f[a + 5] * roll_ref
    state[S_Y + 1] = f[a] * theta_d + f[a + 1] * theta_dd + f[a + 2] * pitch_ref
    state[S_YD + 1] = f[a + 3] * theta_d + f[a + 4] * theta_dd + f[a + 5] * pitch_ref
    return phi_d, theta_d, phi_dd, theta_dd, phi_ddd, theta_ddd
