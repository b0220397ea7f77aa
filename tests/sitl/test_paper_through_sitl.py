"""Issue "missions and gusts": the paper's experiment through the SITL, and gust uploads to the
running simulator, over the real wire (MAVLink/UDP, zenoh), checked from the recorded logs.
"""

import json
import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as m

from gcs_scripts.analysis.log_reader import read_session
from gcs_scripts.analysis.metrics import indices
from gcs_scripts.upload_gusts import upload_gusts
from quadcommon.bus_records import TRUTH_FIELDS
from quadcommon.config import load_controller, load_scenario
from sitl.demo import fly_one
from sitl.inprocess import run_scenario

from .harness import Sitl

T = {name: i for i, name in enumerate(TRUTH_FIELDS)}
TRANSIENT_S = 4.0


def test_gust_uploads_are_validated_and_move_the_vehicle():
    drag = ("--vehicle", "paper_quad_drag")
    with Sitl(13, scenario="hover", collect=True, sim_args=drag, ap_args=drag) as sitl:
        gcs = sitl.gcs()
        try:
            gcs.wait_heartbeat()
            assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED
            gcs.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, math.nan)
            gcs.wait(
                lambda g: "LOCAL_POSITION_NED" in g.last and g.position()[2] > 2.45,
                sim_timeout=15,
                what="hovering at the takeoff altitude",
            )
            t_hover = gcs.sim_time + 2.0
            gcs.wait(lambda g: g.sim_time > t_hover, what="settled")

            bad = {
                "one_minus_cosine": [
                    {"start_s": 0.5, "duration_s": 2.0, "amplitude_m_s": 3.0, "direction": [0.0, 0.0, 0.0]}
                ]
            }
            answer = upload_gusts(bad, 13, "now", timeout=5.0, session=sitl.session)
            assert answer["accepted"] is False
            assert "profile.one_minus_cosine[0].direction" in answer["error"]

            gust = {
                "one_minus_cosine": [{"start_s": 0.5, "duration_s": 2.0, "amplitude_m_s": 4.0, "axis": "x"}]
            }
            answer = upload_gusts(gust, 13, "now", timeout=5.0, session=sitl.session)
            assert answer["accepted"] is True and "warning" not in answer
            start = answer["start_s"]
            gcs.wait(lambda g: g.sim_time > start + 6.0, what="the gust and the recovery")
        finally:
            gcs.close()
        truth = sitl.truth()
    t = truth[:, T["time_s"]]
    during = (t >= start + 0.5) & (t <= start + 2.5)
    wind = truth[:, T["wind_x_m_s"]]
    assert wind[during].max() == pytest.approx(4.0, abs=0.01)  # the applied wind is in the ground truth
    assert np.all(wind[t < start] == 0.0)
    x = truth[:, T["x_m"]]
    before = x[(t > start - 1.0) & (t < start)].mean()
    pushed = np.abs(x[(t >= start) & (t <= start + 4.0)] - before).max()
    assert pushed > 0.005, f"the gust moved the vehicle by only {pushed * 1000:.2f} mm"
    assert abs(x[t > start + 5.5].mean() - before) < 0.003  # and the integral action brought it back


@pytest.mark.parametrize("controller, instance", [("intbs_nlhinf", 14), ("bs_nlhinf", 15)])
def test_paper_helix_through_the_sitl_matches_the_in_process_run(controller, instance, tmp_path):
    """Mission + gust upload + recording; indices from the log only, beside the in-process run."""
    log = tmp_path / f"helix_{controller}"
    t0 = fly_one(controller, "helix", instance, log, speed="max")  # what make demo runs
    sidecar = json.loads((tmp_path / f"helix_{controller}.flight.json").read_text())
    assert sidecar["t0_s"] == pytest.approx(t0, abs=1e-3)
    duration = load_scenario("helix").duration_s
    sitl = read_session(log.with_suffix(".parquet"), window=(t0, duration))
    inproc = run_scenario(load_scenario("helix"), load_controller(controller))
    final = np.abs(sitl.position_error_m[-1])
    if controller == "intbs_nlhinf":
        assert final.max() < 1e-3  # the paper's pattern: under 1 mm on every axis
    else:
        assert final.max() >= 1e-2  # BS-NLHinf keeps a centimetre offset
    # After the start-up transient (the SITL joins the curve from a hover, the in-process run from
    # the paper's initial state) the ISE agree within 10 % on every state.
    a = indices(sitl.window(TRANSIENT_S, duration)).ise
    b = indices(inproc.window(TRANSIENT_S, duration)).ise
    for state in a:
        assert a[state] == pytest.approx(b[state], rel=0.10), (state, a[state], b[state])
    # the disturbance schedule hit at the in-process instants (within one control step)
    assert sitl.event_times_s == pytest.approx(inproc.event_times_s, abs=0.0021)
