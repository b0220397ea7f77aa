"""Scalar helpers the kernels share (:mod:`quadcommon.kernel`)."""

from __future__ import annotations

from .kernel import kernel


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
