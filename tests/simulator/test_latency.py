"""The round-trip histogram (simulator/latency.py): quantiles within its resolution, constant memory."""

import math
import random

from simulator.latency import BINS_PER_DECADE, LatencyHistogram


def test_quantiles_agree_with_the_sorted_samples_within_one_bin():
    rng = random.Random(3)
    samples = [rng.lognormvariate(-9.0, 0.7) for _ in range(50_000)] + [2.0, 1e-9, 500.0]
    hist = LatencyHistogram()
    for s in samples:
        hist.add(s)
    samples.sort()
    step = 10.0 ** (1.0 / BINS_PER_DECADE)
    for q in (0.5, 0.9, 0.99):
        exact = samples[int(q * len(samples))]
        assert exact / step <= hist.quantile(q) <= exact * step
    assert len(hist) == len(samples) and len(hist.counts) == 801  # the same size after any run
    assert math.isnan(LatencyHistogram().quantile(0.5))
