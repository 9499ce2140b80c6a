"""What pyproject.toml declares matches the package: its imports and its one version."""

import ast
import importlib.metadata as md
import re
import sys
from pathlib import Path

import pytest

import segparam

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"
PACKAGE = Path(segparam.__file__).resolve().parent


def _name(requirement: str) -> str:
    """The normalized distribution name of a requirement (``dask[distributed]>=1`` -> dask)."""
    return re.sub(r"[-_.]+", "-", re.match(r"[A-Za-z0-9_.-]+", requirement).group()).lower()


def _third_party_imports() -> set[str]:
    modules = set()
    for path in PACKAGE.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                modules |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                modules.add(node.module.split(".")[0])
    return {m for m in modules if m not in sys.stdlib_module_names and m != "segparam"}


def test_every_import_is_declared_and_every_dependency_is_imported():
    project = tomllib.loads(PYPROJECT.read_text(encoding="utf-8"))["project"]
    required = {_name(r) for r in project["dependencies"]}
    optional = {_name(r) for r in project["optional-dependencies"]["batch"]}
    distributions = md.packages_distributions()
    imported = {_name(distributions.get(module, [module])[0]) for module in _third_party_imports()}
    assert imported - required - optional == set()  # an import nobody installs
    assert required - imported == set()  # a dependency nothing imports (networkx was one)


def test_the_version_is_written_once_in_the_package():
    project = tomllib.loads(PYPROJECT.read_text(encoding="utf-8"))
    assert "version" not in project["project"] and "version" in project["project"]["dynamic"]
    attr = project["tool"]["setuptools"]["dynamic"]["version"]["attr"]
    assert attr == "segparam.__version__"
    try:
        installed = md.version("segparam")
    except md.PackageNotFoundError:
        pytest.skip("segparam is not installed")
    assert installed == segparam.__version__
