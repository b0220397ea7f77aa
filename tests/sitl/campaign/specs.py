"""Campaign specs written by the tests (so the tests do not move when the examples change)."""

from __future__ import annotations

from pathlib import Path

BOX = """
name = "test_box"
scenario = "helix"
controllers = ["intbs_nlhinf", "intbs", "bs_nlhinf"]
runs = 6
seed = 99
chunk_runs = {chunk}
duration_s = {duration}

[plant]
mass_scale = {{ uniform = [0.7, 1.3] }}
inertia_scale = [{{ uniform = [0.7, 1.3] }}, {{ uniform = [0.7, 1.3] }}, {{ uniform = [0.7, 1.3] }}]

[initial_state]
position_offset_m = [{{ uniform = [-0.1, 0.1] }}, {{ uniform = [-0.1, 0.1] }}, {{ uniform = [-0.1, 0.1] }}]
euler_offset_rad = [{{ uniform = [-0.05, 0.05] }}, 0.0, {{ uniform = [-0.3, 0.3] }}]

[disturbances]
base = "none"

[[disturbances.step]]
channel = "force_x"
start_s = {{ uniform = [1.0, 3.0] }}
value = {{ uniform = [0.5, 1.5] }}

[[disturbances.step]]
channel = "torque_roll"
start_s = {{ uniform = [2.0, 4.0] }}
value = {{ uniform = [0.5, 1.5] }}

[[disturbances.step]]
channel = "torque_yaw"
start_s = {{ uniform = [3.0, 6.0] }}
end_s = {{ uniform = [20.0, 30.0] }}
value = {{ uniform = [-1.0, 1.0] }}
"""

WIND = """
name = "test_wind"
scenario = "circle"
vehicle = "paper_quad_drag"
controllers = ["intbs_nlhinf", "bs_nlhinf"]
runs = 4
seed = 3
duration_s = {duration}

[plant]
mass_scale = {{ uniform = [0.8, 1.2] }}
inertia_scale = {{ uniform = [0.8, 1.2] }}
com_offset_m = [{{ uniform = [-0.02, 0.02] }}, {{ uniform = [-0.02, 0.02] }}, {{ uniform = [-0.04, 0.0] }}]
products_of_inertia_kg_m2 = [{{ uniform = [-2e-4, 2e-4] }}, {{ uniform = [-2e-4, 2e-4] }}, 0.0]

[initial_state]
velocity_m_s = [{{ uniform = [-0.3, 0.3] }}, 0.0, 0.0]

[disturbances]
base = "paper_steps"

[[disturbances.ramp]]
channel = "force_y"
start_s = {{ uniform = [1.0, 2.0] }}
end_s = {{ uniform = [4.0, 5.0] }}
value = {{ uniform = [-0.5, 0.5] }}

[[disturbances.one_minus_cosine]]
start_s = {{ uniform = [2.0, 6.0] }}
duration_s = {{ uniform = [1.0, 3.0] }}
amplitude_m_s = {{ uniform = [2.0, 5.0] }}
direction = [1.0, {{ uniform = [-1.0, 1.0] }}, 0.0]

[disturbances.dryden]
w20_m_s = {{ uniform = [5.0, 15.0] }}
altitude_m = 2.5
start_s = 1.0
"""

ROTORS = """
name = "test_rotors"
scenario = "hover"
vehicle = "paper_quad_rotors"
controllers = ["intbs_nlhinf", "intbs"]
runs = 4
seed = 17
duration_s = {duration}

[plant]
mass_scale = {{ uniform = [0.8, 1.2] }}
thrust_coefficient_scale = {{ uniform = [0.9, 1.1] }}
drag_coefficient_scale = {{ uniform = [0.9, 1.1] }}
rotor_time_constant_scale = {{ uniform = [0.5, 2.0] }}

[initial_state]
position_offset_m = [0.0, 0.0, 2.5]   # start at the hover point (rotors at rest)

[disturbances]
base = "none"

[[disturbances.step]]
channel = "force_x"
start_s = {{ uniform = [3.0, 5.0] }}
value = {{ uniform = [-0.5, 0.5] }}
"""


def write(tmp_path: Path, template: str, name: str, **fields) -> Path:
    defaults = {"chunk": 2, "duration": 40.0}
    defaults.update(fields)
    path = tmp_path / f"{name}.toml"
    path.write_text(template.format(**defaults))
    return path
