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
from quadcommon.layout import Field, layout
from quadcommon.layout import values as layout_values

# Coefficients, from an offset into the cascade's array: on/off, wn^2, 2 zeta wn, the first two rows
# of the discrete transition (a00, a01, a02, a10, a11, a12) of [y, y', r].
FILTER_COEFFICIENTS = layout("CommandFilterCoefficients", (
    Field("on"),
    Field("omega_n_squared"),
    Field("two_zeta_omega"),
    Field("phi", 6),
))  # fmt: skip
# State: y (roll, pitch), y' (roll, pitch), initialised (1.0 / 0.0).
FILTER_STATE = layout("CommandFilterState", (
    Field("y", 2),
    Field("y_dot", 2),
    Field("ready"),
))  # fmt: skip


def discretise(
    natural_frequency_rad_s: float, damping: float, dt: float, enabled: bool = True
) -> tuple[float, ...]:
    """The filter's coefficients (:data:`FILTER_COEFFICIENTS`) for the control period ``dt``."""
    import numpy as np
    from scipy.linalg import expm  # here: importing scipy

    wn2 = natural_frequency_rad_s**2
    two_zeta_wn = 2.0 * damping * natural_frequency_rad_s
    # Augmented continuous system [y, y', r]' with r constant over the step.
    A = np.array([[0.0, 1.0, 0.0], [-wn2, -two_zeta_wn, wn2], [0.0, 0.0, 0.0]])
    phi = expm(A * dt)[:2].ravel()
    on = 1.0 if enabled else 0.0
    phi_values = [float(v) for v in phi]
    return layout_values(
        FILTER_COEFFICIENTS, on=on, omega_n_squared=wn2, two_zeta_omega=two_zeta_wn, phi=phi_values
    )


@kernel
def advance(f, offset, state, roll_ref, pitch_ref):
    """``(phi_d, theta_d, phi_d', theta_d', phi_d'', theta_d'')`` now, for the references held over
    the next step, then the state advanced by one step. The first step starts at the references,
    at rest."""
    if f[offset + FILTER_COEFFICIENTS.on] == 0.0:
        return roll_ref, pitch_ref, 0.0, 0.0, 0.0, 0.0
    if state[FILTER_STATE.ready] == 0.0:
        state[FILTER_STATE.y], state[FILTER_STATE.y + 1] = roll_ref, pitch_ref
        state[FILTER_STATE.y_dot], state[FILTER_STATE.y_dot + 1] = 0.0, 0.0
        state[FILTER_STATE.ready] = 1.0
    phi_d, theta_d = state[FILTER_STATE.y], state[FILTER_STATE.y + 1]
    phi_dd, theta_dd = state[FILTER_STATE.y_dot], state[FILTER_STATE.y_dot + 1]
    wn2 = f[offset + FILTER_COEFFICIENTS.omega_n_squared]
    two_zeta_wn = f[offset + FILTER_COEFFICIENTS.two_zeta_omega]
    phi_ddd = wn2 * (roll_ref - phi_d) - two_zeta_wn * phi_dd
    theta_ddd = wn2 * (pitch_ref - theta_d) - two_zeta_wn * theta_dd
    a = offset + FILTER_COEFFICIENTS.phi
    state[FILTER_STATE.y] = f[a] * phi_d + f[a + 1] * phi_dd + f[a + 2] * roll_ref
    state[FILTER_STATE.y_dot] = f[a + 3] * phi_d + f[a + 4] * phi_dd + f[a + 5] * roll_ref
    state[FILTER_STATE.y + 1] = f[a] * theta_d + f[a + 1] * theta_dd + f[a + 2] * pitch_ref
    state[FILTER_STATE.y_dot + 1] = f[a + 3] * theta_d + f[a + 4] * theta_dd + f[a + 5] * pitch_ref
    return phi_d, theta_d, phi_dd, theta_dd, phi_ddd, theta_ddd
