"""The control law docs/controllers.md shows a researcher ("Adding a control law") is a law that
loads: its file and its controller file, copied from the page into a configuration directory,
register, pack their gains by name and steer back towards the reference (its step run as Python:
compiling a new law pair costs the suite tens of CPU seconds; the own-law tests fly one)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from autopilot.control import registry
from autopilot.control.cascade import pack
from autopilot.control.config import load_controller
from quadcommon.config import load_vehicle
from tests.own_law import laws_forgotten_afterwards

pytestmark = pytest.mark.timeout(60)

PAGE = Path(__file__).resolve().parents[2] / "docs" / "controllers.md"


def _block_after(text: str, marker: str, language: str) -> str:
    start = text.index(marker)
    match = re.compile(rf"```{language}\n(.*?)```", re.S).search(text, start)
    assert match is not None, f"no {language} block after {marker!r}"
    return match.group(1)


def test_the_pages_own_law_loads_packs_its_gains_by_name_and_steers(tmp_path):
    text = PAGE.read_text()
    (tmp_path / "laws").mkdir()
    (tmp_path / "controllers").mkdir()
    (tmp_path / "laws" / "my_pd.py").write_text(_block_after(text, "laws/my_pd.py`:", "python"))
    toml = _block_after(text, "controllers/my_pd.toml`:", "toml")
    (tmp_path / "controllers" / "my_pd.toml").write_text(toml)
    with laws_forgotten_afterwards(tmp_path):
        controller = load_controller("my_pd")
        packed = pack(controller, load_vehicle("paper_quad"), 0.002)
        law = registry.law(registry.TRANSLATIONAL, "my_pd")
        module = __import__(law.__module__, fromlist=["GAINS"])
        assert packed.gt[module.GAINS.kp] == 20.0 and packed.gt[module.GAINS.kd] == 9.0
        zero = (0.0, 0.0, 0.0)
        below = law.step(packed.gt, (), (0.0, 0.0, 0.9), zero, zero, (0.0, 0.0, 1.0), zero, zero, 0.0,
                         0.002, True)  # fmt: skip
        thrust, roll, pitch, a_x, a_y, a_z = below[:6]
        assert a_z == pytest.approx(20.0 * 0.1) and thrust > packed.context.mass_kg * 9.81
        assert (roll, pitch, a_x, a_y) == (0.0, 0.0, 0.0, 0.0)
