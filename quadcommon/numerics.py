"""Numeric helpers the kernels share (:mod:`quadcommon.kernel`): clipping, a filtered derivative."""

from __future__ import annotations

import math

from .kernel import kernel
from .layout import Field, layout


@kernel
def clip(x: float, lo: float, hi: float) -> float:
    """``x`` limited to ``[lo, hi]``; NaN passes through (a failing law stays visible), in Python
    and compiled alike (the builtins ``min``/``max`` treat NaN differently in the two)."""
    if x < lo:
        return lo
    if x > hi:
        return hi
    return x


@kernel
def clip_symmetric(x: float, bound: float) -> float:
    """``x`` limited to ``[-bound, bound]`` (an anti-windup clamp); NaN passes through."""
    if x > bound:
        return bound
    if x < -bound:
        return -bound
    return x


def low_pass_alpha(cutoff_hz: float, dt: float) -> float:
    """Weight of the new sample in the first-order low pass ``y += alpha (u - y)`` of cutoff
    ``cutoff_hz`` sampled every ``dt`` s (PX4's BlockLowPass: ``b = 2 pi f dt``,
    ``alpha = b / (1 + b)``); 1.0, no filtering, for a cutoff of 0."""
    if cutoff_hz <= 0.0:
        return 1.0
    b = 2.0 * math.pi * cutoff_hz * dt
    return b / (1.0 + b)


# A filtered derivative's state, from its offset in a law's state.
DERIVATIVE = layout("FilteredDerivative", (
    Field("previous", 3, doc="the previous sample"),
    Field("filtered", 3, doc="the filtered derivative"),
    Field("ready", doc="1.0 once a sample is held"),
))  # fmt: skip


def derivative_names(signal: str) -> tuple[str, ...]:
    """Names of a filtered derivative's state entries (for a law's STATE), e.g. ``vel_prev_x``."""
    previous, filtered = (f"{signal}_prev_{a}" for a in "xyz"), (f"{signal}_dot_{a}" for a in "xyz")
    return (*previous, *filtered, f"{signal}_dot_ready")


@kernel
def filtered_derivative(x, at, values, alpha, dt, integrate):
    """The time derivative of a 3-vector signal sampled every ``dt`` s: the difference of two
    samples over ``dt``, low-passed with weight ``alpha`` (:func:`low_pass_alpha`), as PX4's
    BlockDerivative. Its state is ``x[at:at + DERIVATIVE.size]``; the first sample gives zero
    (nothing to differentiate yet). The state advances only when ``integrate``."""
    f = at + DERIVATIVE.filtered
    if x[at + DERIVATIVE.ready] == 0.0:
        d0, d1, d2 = 0.0, 0.0, 0.0
    else:
        d0 = x[f] + alpha * ((values[0] - x[at]) / dt - x[f])
        d1 = x[f + 1] + alpha * ((values[1] - x[at + 1]) / dt - x[f + 1])
        d2 = x[f + 2] + alpha * ((values[2] - x[at + 2]) / dt - x[f + 2])
    if integrate:
        x[at], x[at + 1], x[at + 2] = values[0], values[1], values[2]
        x[f], x[f + 1], x[f + 2] = d0, d1, d2
        x[at + DERIVATIVE.ready] = 1.0
    return d0, d1, d2
