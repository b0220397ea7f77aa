"""Every public function and class documents itself (as python-control's docstring test does).

Public: no leading underscore, defined in the module that is walked (not imported into it), and
listed in ``__all__`` where the module has one; a public class's public methods and properties
too (a docstring inherited from the method it overrides counts). The packages covered are in
``DOCUMENTED``: every package of the product.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

pytestmark = pytest.mark.timeout(120)

DOCUMENTED = ("quadcommon", "simulator", "gcs_scripts", "sitl", "autopilot")

def modules(package: str):
    root = importlib.import_module(package)
    yield root
    for info in pkgutil.walk_packages(root.__path__, f"{package}."):
        if info.name.endswith("__main__"):
            continue
        yield importlib.import_module(info.name)


def _defined_here(obj, module) -> bool:
    return getattr(obj, "__module__", None) == module.__name__


def undocumented(package: str) -> list[str]:
    """``module.name`` of every public function, class, method and property without a docstring."""
    missing = []
    for module in modules(package):
        listed = getattr(module, "__all__", None)
        for name, obj in vars(module).items():
            if name.startswith("_") or (listed is not None and name not in listed):
                continue
            if not (inspect.isfunction(obj) or inspect.isclass(obj)) or not _defined_here(obj, module):
                continue
            if not inspect.getdoc(obj):
                missing.append(f"{module.__name__}.{name}")
            if inspect.isclass(obj):
                for attr, member in vars(obj).items():
                    method = inspect.isfunction(member) or isinstance(member, property)
                    if attr.startswith("_") or not method:
                        continue
                    if not inspect.getdoc(getattr(obj, attr)):
                        missing.append(f"{module.__name__}.{name}.{attr}")
    return missing


@pytest.mark.parametrize("package", DOCUMENTED)
def test_every_public_function_and_class_documents_itself(package):
    assert undocumented(package) == []

