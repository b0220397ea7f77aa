"""The accuracies the filter reports (ESTIMATOR_STATUS, the recorder's ``pos_*_accuracy_m``) against
its real error, on the shipped sensor and estimator profiles as a user gets them (no matched
noise figures), over seeds, in simulation time.

Honest means: not optimistic (at least 90 % of the airborne samples inside 3 sigma, horizontally
and vertically), not uselessly pessimistic (the median reported 1-sigma at most 3x the RMS error of
its axes), the position NEES averaged over the seeds in its chi-square band, and never "converged"
while the estimate is known to be far off (just after the alignment on one GNSS fix).
"""

from __future__ import annotations

import dataclasses
import math
from functools import cache

import numpy as np
import pytest
from scipy.stats import chi2

from autopilot.estimation import load_estimator_params
from autopilot.estimation.kernels import IP
from simulator.sensors import load_sensors

from .helpers import helix_truth, run_filter

pytestmark = pytest.mark.timeout(300)

PRE_S = 2.0  # on the stand at the start pose (the alignment), then the helix
FLIGHT_S = 20.0
SEEDS = 20
EVERY = 10  # frames between samples (50 Hz, the telemetry's rate)


@dataclasses.dataclass
class Samples:
    """One row per sample and seed: time, position error (true - estimate), reported 1-sigmas,
    converged, position NEES (3 states)."""

    seed: np.ndarray
    t: np.ndarray
    err: np.ndarray  # (n, 3)
    sigma_h: np.ndarray
    sigma_v: np.ndarray
    converged: np.ndarray
    nees: np.ndarray

    @property
    def err_h(self) -> np.ndarray:
        return np.hypot(self.err[:, 0], self.err[:, 1])

    @property
    def err_v(self) -> np.ndarray:
        return np.abs(self.err[:, 2])


@cache
def fly(profile: str, seeds: int = SEEDS, flight_s: float = FLIGHT_S) -> Samples:
    truth = helix_truth(40.0, PRE_S)[: round((PRE_S + flight_s) * 500)]
    by_time = {round(t * 1e6): s for t, s in truth}
    params = load_estimator_params(profile)
    rows: list[tuple[float, ...]] = []
    for seed in range(seeds):

        def sample(t, ekf, seed=seed):
            if round(t * 500) % EVERY:
                return
            e = np.subtract(by_time[round(t * 1e6)].position_m, ekf.estimate().position_m)
            status = ekf.status()
            nees = float(e @ np.linalg.solve(ekf.P[IP : IP + 3, IP : IP + 3], e))
            rows.append((seed, t, *e, status.pos_horiz_accuracy_m, status.pos_vert_accuracy_m,
                         float(status.converged), nees))  # fmt: skip

        sensors = dataclasses.replace(load_sensors(profile), seed=seed)
        run_filter(truth, sensors, params, nees_every=10**9, each_frame=sample)
    a = np.array(rows)
    return Samples(a[:, 0].astype(int), a[:, 1], a[:, 2:5], a[:, 5], a[:, 6], a[:, 7] > 0.0, a[:, 8])


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x * x)))


@pytest.mark.parametrize("profile", ["gps", "mocap"])
def test_reported_accuracies_are_neither_optimistic_nor_3x_pessimistic(profile):
    s = fly(profile)
    air = s.t >= PRE_S
    eh, ev, sh, sv = s.err_h[air], s.err_v[air], s.sigma_h[air], s.sigma_v[air]
    inside_h, inside_v = np.mean(eh <= 3.0 * sh), np.mean(ev <= 3.0 * sv)
    ratio_h, ratio_v = np.median(sh) / rms(eh), np.median(sv) / rms(ev)
    print(f"{profile}: horizontal RMS {rms(eh) * 1e3:.2f} mm, median 1-sigma {np.median(sh) * 1e3:.2f} mm "
          f"({inside_h:.1%} inside 3 sigma); vertical RMS {rms(ev) * 1e3:.2f} mm, median 1-sigma "
          f"{np.median(sv) * 1e3:.2f} mm ({inside_v:.1%} inside 3 sigma)")  # fmt: skip
    assert inside_h >= 0.9 and inside_v >= 0.9
    assert ratio_h <= 3.0 and ratio_v <= 3.0
    # And per seed: no run where the filter is optimistic as a whole.
    for seed in range(SEEDS):
        mine = s.seed[air] == seed
        assert np.mean(eh[mine] <= 3.0 * sh[mine]) >= 0.9, seed


def test_on_exact_sensors_the_estimate_is_the_truth_and_never_optimistic():
    """``ideal`` (the default profile): exact sensors, and a GPS that reports a 1 m accuracy (a
    receiver never claims less than its resolution): the estimate is the truth to a millimetre,
    so only the first half of the criteria applies (never optimistic)."""
    s = fly("ideal", seeds=1)
    air = s.t >= PRE_S
    eh, ev = s.err_h[air], s.err_v[air]
    assert rms(eh) < 1e-3 and rms(ev) < 1e-3
    assert np.mean(eh <= 3.0 * s.sigma_h[air]) >= 0.9 and np.mean(ev <= 3.0 * s.sigma_v[air]) >= 0.9
    assert s.converged[s.t >= PRE_S + 1.0].all()  # (the stand's 2 s align it; converged within 1 s more)


@pytest.mark.parametrize("profile", ["gps", "mocap"])
def test_position_nees_over_seeds_is_in_its_chi_square_band(profile):
    """At each sample time the NEES of the 3 position states averaged over the seeds, times the
    seed count, is chi2(3 x seeds) for a consistent filter: its mean over the flight lies in the
    95 % band, and most sample times do (the times are correlated: not all of them)."""
    s = fly(profile)
    air = s.t >= PRE_S
    times = np.unique(np.round(s.t[air], 6))
    per_time = np.array([s.nees[air][np.round(s.t[air], 6) == t].mean() for t in times])
    lo, hi = chi2.ppf(0.025, 3 * SEEDS) / SEEDS, chi2.ppf(0.975, 3 * SEEDS) / SEEDS
    inside = np.mean((per_time >= lo) & (per_time <= hi))
    print(f"{profile}: position NEES over {SEEDS} seeds, mean {per_time.mean():.2f}, band [{lo:.2f}, "
          f"{hi:.2f}], {inside:.0%} of the times inside")  # fmt: skip
    assert lo <= per_time.mean() <= hi
    assert inside >= 0.8


def test_never_converged_while_the_height_is_one_gnss_fix():
    """Aligned on the stand on the gps profile, the first estimate's height is one fix (0.5 m
    1-sigma, reported 0.75 m): in some seeds it is a metre off. The filter waits for the fixes and
    the baro to bring it within EST_CONV_VPOS before it says converged."""
    s = fly("gps", seeds=SEEDS, flight_s=0.0)  # the stand only
    limit = load_estimator_params("gps").converged_vpos_m
    assert s.converged.any()
    assert np.all(s.sigma_v[s.converged] <= limit)
    first = [np.flatnonzero(s.seed == seed)[0] for seed in range(SEEDS)]
    assert max(s.err_v[i] for i in first) > 0.9  # there were estimates known to be far off ...
    assert not any(s.converged[i] for i in first)  # ... and none was reported converged
    assert s.err_v[s.converged].max() <= 3.0 * limit
    converged_at = [s.t[(s.seed == seed) & s.converged].min() for seed in range(SEEDS)]
    assert max(converged_at) < PRE_S  # still fit to arm on the stand, within a second of aligning
    assert not math.isnan(converged_at[0])
