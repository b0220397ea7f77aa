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
"""

from pathlib import Path

from setuptools import find_namespace_packages, find_packages, setup

HERE = Path(__file__).resolve().parent
CODE = ["autopilot*", "simulator*", "gcs_scripts*", "sitl*", "quadcommon*"]
CONFIG = ["quadsitl_config"] + [
    f"quadsitl_config.{p.name}" for p in sorted((HERE / "config").iterdir()) if p.is_dir()
]
STATIC = find_namespace_packages(where=str(HERE), include=["gcs_scripts.view.static*"])

setup(
    packages=[*find_packages(where=str(HERE), include=CODE), *STATIC, *CONFIG],
    package_dir={"quadsitl_config": "config"},
    package_data={
        **{name: ["*.toml"] for name in CONFIG},
        "gcs_scripts.view": ["package.json", "package-lock.json"],
        **{name: ["*"] for name in STATIC},
    },
)
