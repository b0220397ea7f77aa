"""A seeded random stream that kernels draw from: the same numbers in Python and in compiled code.

The sensor models draw their noise from it, in the simulator (a frame at a time) and in a batch
engine's compiled loop alike, so one seed gives one noise sequence wherever the equations run.
Python's :class:`random.Random` and numpy's generators cannot be called from a kernel, and
numba's own ``np.random`` is one global stream per thread that Python code does not share.

The generator is P. L'Ecuyer's MRG32k3a (*Good parameters and implementations for combined
multiple recursive random number generators*, Operations Research 47(1), 1999): two
third-order recurrences modulo primes just below 2^32, combined; period about 2^191; it passes
TestU01's BigCrush. It is written for double-precision arithmetic: every product is below 2^53,
so Python floats and compiled float64 give the same bits. Its state is six floats in a kernel
buffer (:func:`stream`), advanced in place. Normal deviates by Box-Muller, one per two uniforms.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .kernel import kernel, vector

SIZE = 6  # floats of state: s10, s11, s12 (component 1), s20, s21, s22 (component 2)

M1 = 4294967087.0
M2 = 4294944443.0
A12 = 1403580.0
A13N = 810728.0
A21 = 527612.0
A23N = 1370589.0
NORM = 2.328306549295727688e-10  # 1 / (M1 + 1)
TWO_PI = 2.0 * math.pi


@kernel
def uniform(state: Any) -> float:
    """The next uniform deviate in (0, 1) (never 0 or 1); advances ``state`` in place."""
    p1 = A12 * state[1] - A13N * state[0]
    p1 -= float(int(p1 / M1)) * M1
    if p1 < 0.0:
        p1 += M1
    state[0] = state[1]
    state[1] = state[2]
    state[2] = p1
    p2 = A21 * state[5] - A23N * state[3]
    p2 -= float(int(p2 / M2)) * M2
    if p2 < 0.0:
        p2 += M2
    state[3] = state[4]
    state[4] = state[5]
    state[5] = p2
    if p1 <= p2:
        return (p1 - p2 + M1) * NORM
    return (p1 - p2) * NORM


@kernel
def normal(state: Any) -> float:
    """The next standard normal deviate (Box-Muller, two uniforms per deviate)."""
    radius = math.sqrt(-2.0 * math.log(uniform(state)))
    return radius * math.cos(TWO_PI * uniform(state))


def seeded_state(seed: int) -> list[float]:
    """The six state floats for ``seed`` (any non-negative integer), spread by numpy's
    SeedSequence so that nearby seeds give unrelated streams."""
    words = np.random.SeedSequence(int(seed)).generate_state(6, dtype=np.uint64)
    first = [float(int(w) % int(M1)) for w in words[:3]]
    second = [float(int(w) % int(M2)) for w in words[3:]]
    if not any(first):  # a component's state must not be all zero
        first[0] = 1.0
    if not any(second):
        second[0] = 1.0
    return first + second


def stream(seed: int) -> Any:
    """A kernel buffer (:func:`quadcommon.kernel.vector`) holding the stream of ``seed``."""
    return vector(seeded_state(seed))
