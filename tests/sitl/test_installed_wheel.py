"""The package works wherever it is installed : the wheel, built from this checkout,
installed into a fresh virtual environment outside it, run from an empty directory.

Isolation: the venv is new (``python -m venv --without-pip``) and quadsitl goes into it from the
wheel (``pip --python VENV install --no-deps --no-index``). Its dependencies (numpy, pymavlink,
zenoh, ...) are not downloaded again: a ``.pth`` file in the new venv appends the development
environment's site-packages to ``sys.path``. A plain path line in a ``.pth`` does not run the
``.pth`` files of that directory, so the editable install's finder (which would map the packages
to this checkout) stays off; the checks below assert that every package comes from the venv. The
wheel is built from a copy of the source tree (no stale ``build/`` of the checkout in it), with
``--no-build-isolation`` (offline: setuptools is a dev dependency). SITL instances 16 and 18 only.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

from sitl.launcher import Child
from tests.ports import block_config_dir, instance_ports

pytestmark = pytest.mark.processes  # (tests/conftest.py: the markers)

REPO = Path(__file__).resolve().parents[2]
INSTANCE = 16
FLY_INSTANCE = 18
SKIP = (".git", ".venv", "out", "runs", "build", "*.egg-info", "__pycache__", "node_modules",
        ".pytest_cache", ".ruff_cache", "tests", "benchmarks")  # fmt: skip


class Installed:
    def __init__(self, root: Path, wheel: Path) -> None:
        self.root = root
        self.wheel = wheel
        self.venv = root / "venv"
        self.bin = self.venv / "bin"
        self.empty = root / "empty"
        self.empty.mkdir()
        self.env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "QUADSITL_CONFIG_DIR")}
        block = block_config_dir()  # the test process's ports (a sitl.toml alone: the rest is the wheel's)
        if block is not None:
            self.env["QUADSITL_CONFIG_DIR"] = str(block)
        self.env.update(PATH=f"{self.bin}{os.pathsep}{os.environ['PATH']}", VIRTUAL_ENV=str(self.venv))

    def run(self, *args: str, timeout: float = 60.0, env: dict[str, str] | None = None):
        return subprocess.run(
            [str(self.bin / args[0]), *args[1:]], cwd=self.empty, env={**self.env, **(env or {})},
            capture_output=True, text=True, timeout=timeout,
        )  # fmt: skip


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Installed:
    root = tmp_path_factory.mktemp("installed")
    src = root / "src"
    shutil.copytree(REPO, src, ignore=shutil.ignore_patterns(*SKIP))
    wheels = root / "wheels"
    build = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-w",
         str(wheels), str(src)], capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert build.returncode == 0, build.stdout + build.stderr
    (wheel,) = wheels.glob("quadsitl-*.whl")
    venv = root / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=60)
    install = subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(venv / "bin" / "python"), "install", "--no-deps",
         "--no-index", str(wheel)], capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert install.returncode == 0, install.stdout + install.stderr
    purelib = subprocess.run(
        [str(venv / "bin" / "python"), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
        capture_output=True, text=True, check=True, timeout=30,
    ).stdout.strip()  # fmt: skip
    (Path(purelib) / "_quadsitl_test_dependencies.pth").write_text(sysconfig.get_path("purelib") + "\n")
    return Installed(root, wheel)


@pytest.mark.timeout(180)  # the first test builds and installs the wheel (~5 s here)
def test_wheel_carries_the_configuration_and_the_view_and_imports_from_the_venv(installed):
    names = set(zipfile.ZipFile(installed.wheel).namelist())
    shipped = {"quadsitl_config/sitl.toml", "quadsitl_config/scenarios/circle.toml",
               "quadsitl_config/campaigns/paper_box.toml", "gcs_scripts/view/static/index.html"}  # fmt: skip
    assert shipped <= names
    assert not any(n.startswith(("tests/", "config/")) for n in names)
    vendored = sorted((REPO / "gcs_scripts/view/static/vendor").rglob("*.*"))
    for path in vendored:  # the view's JavaScript goes with it when `make view` has built it
        assert path.relative_to(REPO).as_posix() in names
    probe = installed.run("python", "-c", (
        "import autopilot, simulator, sitl, gcs_scripts, quadcommon, quadcommon.config as c\n"
        "for m in (autopilot, simulator, sitl, gcs_scripts, quadcommon): print(m.__file__)\n"
        "print(c.SHIPPED_CONFIG_DIR)"
    ))  # fmt: skip
    assert probe.returncode == 0, probe.stderr
    lines = probe.stdout.split()
    assert len(lines) == 6
    for line in lines:
        assert Path(line).is_relative_to(installed.venv), line
        assert not Path(line).is_relative_to(REPO), line
    assert Path(lines[-1]).name == "quadsitl_config"


@pytest.mark.timeout(60)
def test_version(installed):
    result = installed.run("quadsitl", "--version")
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "quadsitl " + installed.wheel.name.split("-")[1]


@pytest.mark.timeout(120)
def test_paper_writes_its_tables_from_an_empty_directory(installed):
    result = installed.run(
        "quadsitl", "paper", "--out", "out", "--scenarios", "circle", "--controllers", "intbs_nlhinf",
        "--duration", "1", "--workers", "1", timeout=110,
    )  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr
    out = installed.empty / "out"
    for name in ("tables.md", "table1_final_errors.csv", "table2_ise.csv", "table3_iadu.csv"):
        assert (out / name).is_file(), name
    assert "intbs_nlhinf" in (out / "table2_ise.csv").read_text()


@pytest.mark.timeout(90)
def test_up_links_and_stops_at_its_duration(installed):
    result = installed.run("quadsitl", "up", "--duration", "2", "--instance", str(INSTANCE), "--speed", "max",
                           timeout=80)  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr
    assert f"vehicle {INSTANCE} is up" in result.stdout
    assert "simulator: linked with autopilot" in result.stdout
    assert "the simulator reached --duration 2 s" in result.stdout
    assert f"udp {instance_ports(INSTANCE).gcs_remote}" in result.stdout  # sitl.toml's [ports] followed


@pytest.mark.timeout(120)
def test_up_then_fly_setpoints_flies_the_square(installed):
    """The first flight of the README, as installed: ``quadsitl up`` and ``quadsitl fly setpoints``."""
    n = str(FLY_INSTANCE)
    # --speed 4, not max: the script streams setpoints paced on the telemetry, but it must still get
    # the CPU; at max (~20x here) the offboard-loss timeout (1 s simulated) is ~50 ms of wall time,
    # and beside the rest of the suite the script can be starved that long (docs/running.md).
    up = Child("quadsitl up", [str(installed.bin / "quadsitl"), "up", "--instance", n, "--speed", "4"],
               cwd=installed.empty, env=installed.env)  # fmt: skip
    try:
        up.wait_line("Ctrl-C stops", 40.0)
        fly = installed.run("quadsitl", "fly", "setpoints", "--instance", n, timeout=90)
        assert fly.returncode == 0, fly.stdout + fly.stderr
        for k, corner in enumerate(("2.00, 0.00", "2.00, 2.00", "0.00, 2.00", "0.00, 0.00"), 1):
            assert f"reached setpoint {k} ({corner}, 2.50)" in fly.stdout, fly.stdout
        assert fly.stdout.rstrip().endswith("done")
    finally:
        up.stop(10.0)


@pytest.mark.timeout(60)
def test_config_copy_then_a_users_scenario_and_the_missing_name_error(installed):
    mine = installed.empty / "mine"
    copy = installed.run("quadsitl", "config", "copy", str(mine))
    assert copy.returncode == 0, copy.stderr
    assert (mine / "scenarios" / "circle.toml").is_file() and (mine / "sitl.toml").is_file()
    again = installed.run("quadsitl", "config", "copy", str(mine))
    assert again.returncode == 2 and "--force" in again.stderr and "Traceback" not in again.stderr
    hover = (mine / "scenarios" / "hover.toml").read_text()
    (mine / "scenarios" / "my_hover.toml").write_text(hover)
    env = {"QUADSITL_CONFIG_DIR": str(mine)}
    run = installed.run("quadsitl", "run", "my_hover", "--duration", "0.2", env=env)
    assert run.returncode == 0, run.stdout + run.stderr
    missing = installed.run("quadsitl", "run", "nosuch", env=env)
    assert missing.returncode == 2 and "Traceback" not in missing.stderr
    shipped = installed.run("python", "-c", "from quadcommon.config import SHIPPED_CONFIG_DIR as d; print(d)")
    assert "no scenarios named 'nosuch'" in missing.stderr
    assert f"(looked for {mine / 'scenarios' / 'nosuch.toml'}, " in missing.stderr
    assert f", {Path(shipped.stdout.strip()) / 'scenarios' / 'nosuch.toml'});" in missing.stderr
    assert "available: circle, helix, hover, my_hover" in missing.stderr
