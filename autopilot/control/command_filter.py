"""Second-order command filter: eta_d, eta_d', eta_d'' from a stepwise reference.

The inner loop needs the first two derivatives of the roll/pitch references the outer loop
produces (CONTROL.md). Each channel is ``y'' = wn^2 (r - y) - 2 zeta wn y'``, discretised exactly
for a reference held over the control step (zero-order hold), so it is stable at any rate.
"""

from __future__ import annotations

import numpy as np

from .config import CommandFilter


class SecondOrderFilter:
    """A bank of identical exact-discretised second-order filters, one per channel."""

    def __init__(self, config: CommandFilter, dt: float, channels: int = 2) -> None:
        self.dt = dt
        self.retune(config)
        self.channels = channels
        self.value = [0.0] * channels
        self.rate = [0.0] * channels
        self.initialised = False

    def retune(self, config: CommandFilter) -> None:
        """New wn, zeta from the next step on; the state (y, y') is kept, so y is continuous."""
        self.config = config
        wn, zeta = config.natural_frequency_rad_s, config.damping
        self.wn2 = wn * wn
        self.two_zeta_wn = 2.0 * zeta * wn
        # Augmented continuous system [y, y', r]' with r constant over the step.
        A = np.array([[0.0, 1.0, 0.0], [-self.wn2, -self.two_zeta_wn, self.wn2], [0.0, 0.0, 0.0]])
        from scipy.linalg import expm  # here: importing scipy.linalg costs every process start ~0.2 s

        Phi = expm(A * self.dt)
        # Plain floats for the per-step path.
        self._phi = tuple(tuple(float(v) for v in row) for row in Phi[:2])

    def reset(self, values: list[float] | tuple[float, ...] | None = None) -> None:
        """Start at ``values`` at rest (or re-initialise on the next update)."""
        if values is None:
            self.initialised = False
        else:
            self.value = list(values)
            self.rate = [0.0] * self.channels
            self.initialised = True

    def outputs(self, reference: tuple[float, ...]) -> list[tuple[float, float, float]]:
        """``(y, y', y'')`` per channel now, for the reference ``r`` applied over the next step."""
        if not self.initialised:
            self.reset(reference)
        return [
            (y, yd, self.wn2 * (r - y) - self.two_zeta_wn * yd)
            for y, yd, r in zip(self.value, self.rate, reference, strict=True)
        ]

    def advance(self, reference: tuple[float, ...]) -> None:
        """Advance the filter state by one step with ``reference`` held."""
        (a00, a01, a02), (a10, a11, a12) = self._phi
        for i, r in enumerate(reference):
            y, yd = self.value[i], self.rate[i]
            self.value[i] = a00 * y + a01 * yd + a02 * r
            self.rate[i] = a10 * y + a11 * yd + a12 * r
