"""The four rotors' share of the wrench, written once: the allocation's equation, both ways.

Rotors in + configuration, numbered as the plant and the allocation number them: 1 front,
2 right, 3 rear, 4 left; 1 and 3 spin counter-clockwise seen from above (CONTROL.md). With
``s_i = Omega_i^2`` (rad^2/s^2), thrust coefficient ``b`` (N s^2), reaction-torque coefficient
``d`` (N m s^2) and arm ``l`` (m), the wrench about the geometric centre O is

* ``U1 = b (s1 + s2 + s3 + s4)``,
* ``tau_x = l b (s4 - s2)``, ``tau_y = l b (s3 - s1)``,
* ``tau_z = d (-s1 + s2 - s3 + s4)``  (:func:`wrench_from_squares`),

and its inverse (:func:`squared_speed_parts`) splits each ``s_i`` into a collective part
``U1 / (4 b)``, a roll/pitch part and a yaw part, the split the autopilot's allocation saturates
in that order (:mod:`autopilot.control.allocation`). The plant reads the same two functions:
the rotors' wrench from their speeds (:func:`simulator.dynamics.equations.rotor_wrench`), and on
the ideal-wrench vehicle each rotor's share of the commanded wrench, so that a rotor can fail there
too (:func:`simulator.dynamics.equations.faulted_wrench`). One equation for the autopilot and the
simulator, neither importing the other.
"""

from __future__ import annotations

from .kernel import kernel


@kernel
def wrench_from_squares(b: float, d: float, arm: float, s1: float, s2: float, s3: float, s4: float) -> tuple:
    """``(U1, tau_x, tau_y, tau_z)`` of rotors 1-4 at squared speeds ``s1`` .. ``s4`` (see the
    module: + configuration, body front-left-up)."""
    return b * (s1 + s2 + s3 + s4), arm * b * (s4 - s2), arm * b * (s3 - s1), d * (-s1 + s2 - s3 + s4)


@kernel
def squared_speed_parts(
    b: float, d: float, arm: float, thrust: float, tx: float, ty: float, tz: float
) -> tuple:
    """The squared rotor speeds that give ``(U1, tau)`` exactly, in three parts:
    ``(collective, roll/pitch (4), yaw (4))``, ``s_i = collective + roll/pitch_i + yaw_i``
    (the inverse of :func:`wrench_from_squares`)."""
    base = thrust / (4.0 * b)
    rp = (-ty / (2.0 * arm * b), -tx / (2.0 * arm * b), ty / (2.0 * arm * b), tx / (2.0 * arm * b))
    yaw = (-tz / (4.0 * d), tz / (4.0 * d), -tz / (4.0 * d), tz / (4.0 * d))
    return base, rp, yaw
