"""The package list (everything else is in pyproject.toml).

* The code's packages, found.
* ``quadsitl_config``: the top-level ``config/`` directory (edited there, and only there),
  installed under that name with its subdirectories (``quadsitl_config.scenarios``, ...) as
  data-only packages of TOML files; quadcommon/config.py finds it when there is no checkout.
* ``gcs_scripts.view.static``: the live view's page, and the JavaScript ``make view`` vendors
  into ``static/vendor/`` (shipped when it is there when the wheel is built).

pyproject.toml alone cannot add a package that ``find`` does not see, nor one whose directory is
named otherwise; each data directory is listed as a package so setuptools installs it without
its "absent from the packages configuration" warning.

A wheel built from a checkout carries the checkout's git commit (``quadcommon/GIT_COMMIT``, read
by ``quadcommon/build_info.py``, which reports it in ``AUTOPILOT_VERSION``).
"""

import importlib.util
from pathlib import Path

from setuptools import find_namespace_packages, find_packages, setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent
CODE = ["autopilot*", "simulator*", "gcs_scripts*", "sitl*", "quadcommon*"]
CONFIG = ["quadsitl_config"] + [
    f"quadsitl_config.{p.name}" for p in sorted((HERE / "config").iterdir()) if p.is_dir()
]
STATIC = find_namespace_packages(where=str(HERE), include=["gcs_scripts.view.static*"])


def _build_info():
    """quadcommon/build_info.py, loaded from its file (standard library only: no package import)."""
    path = HERE / "quadcommon" / "build_info.py"
    spec = importlib.util.spec_from_file_location("_quadsitl_build_info", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class BuildWithCommit(build_py):
    """The packages as usual, plus the checkout's commit in the built ``quadcommon`` (if any)."""

    def run(self) -> None:
        super().run()
        info = _build_info()
        commit = info.checkout_commit(HERE / ".git")
        if commit is not None:
            (Path(self.build_lib) / "quadcommon" / info.COMMIT_FILE).write_text(commit + "\n")


setup(
    cmdclass={"build_py": BuildWithCommit},
    packages=[*find_packages(where=str(HERE), include=CODE), *STATIC, *CONFIG],
    package_dir={"quadsitl_config": "config"},
    package_data={
        **{name: ["*.toml"] for name in CONFIG},
        "gcs_scripts.view": ["package.json", "package-lock.json"],
        **{name: ["*"] for name in STATIC},
    },
)
