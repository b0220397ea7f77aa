"""Without numba (QUADSITL_PURE_PYTHON=1) the cascade runs the very same source as Python: over a
closed-loop flight of the nominal model it gives what the compiled cascade gives, to rounding."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from autopilot.control.config import PAPER_CONTROLLERS
from quadcommon.kernel import compiling

FLIGHT = '''
import json, math, sys
from autopilot.control.cascade import Cascade
from autopilot.records import StateEstimate
from autopilot.control.config import load_controller
from quadcommon.config import load_vehicle
from quadcommon.kernel import compiling
from quadcommon.trajectories import Reference

# A point mass with the cascade's U1 along its tilt, and the attitude following the filtered
# references with the cascade's torques: enough of a loop for every law to act and integrate.
cascade = Cascade(load_controller(sys.argv[1]), load_vehicle("paper_quad"), 0.002)
p, v, eta, eta_dot = [0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.2], [0.0, 0.0, 0.0]
rows = []
for k in range(600):
    t = k * 0.002
    s, c = 0.5 * math.sin(t), 0.5 * math.cos(t)
    ref = Reference((s, 0.3, 1.5), (c, 0.0, 0.0), (-s, 0.0, 0.0), 0.1 * t, 0.1, 0.0)
    out = cascade.step(StateEstimate(tuple(p), tuple(v), tuple(eta), tuple(eta_dot)), ref)
    for i in range(3):
        eta_dot[i] += 0.002 * out.torque_euler_n_m[i] / (0.004, 0.004, 0.0084)[i]
        eta[i] += 0.002 * eta_dot[i]
    acc = (out.thrust_n * math.sin(eta[1]) / 0.74, -out.thrust_n * math.sin(eta[0]) / 0.74,
           out.thrust_n * math.cos(eta[0]) * math.cos(eta[1]) / 0.74 - 9.81)
    for i in range(3):
        v[i] += 0.002 * acc[i]
        p[i] += 0.002 * v[i]
    rows.append([out.thrust_n, *out.torque_body_n_m, *out.actuator_controls, *out.euler_ref_rad])
print(json.dumps({"compiled": compiling(), "rows": rows}))
'''


def fly(controller: str, pure_python: bool) -> tuple[bool, np.ndarray]:
    env = {**os.environ, "QUADSITL_PURE_PYTHON": "1" if pure_python else "0"}
    out = subprocess.run([sys.executable, "-c", FLIGHT, controller], capture_output=True, text=True,
                         timeout=300, env=env)  # fmt: skip
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout.strip().splitlines()[-1])
    return result["compiled"], np.array(result["rows"])


@pytest.mark.timeout(600)
@pytest.mark.skipif(not compiling(), reason="numba is not installed or QUADSITL_PURE_PYTHON=1")
@pytest.mark.parametrize("controller", PAPER_CONTROLLERS)
def test_python_and_compiled_fly_the_same_source_alike(controller):
    compiled_flag, compiled = fly(controller, pure_python=False)
    python_flag, python = fly(controller, pure_python=True)
    assert compiled_flag and not python_flag
    assert np.abs(compiled[:, 1:4]).max() > 1e-3  # the laws acted
    assert np.allclose(python, compiled, rtol=1e-9, atol=1e-12)
