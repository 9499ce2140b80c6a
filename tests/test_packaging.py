"""What pyproject.toml declares matches the package: its imports and its one version."""

import ast
import importlib.metadata as md
import json
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


def test_the_tests_import_the_installed_package_not_the_source_tree():
    """CI installs segparam (not editable) and runs plain ``pytest``, which does not put the
    repository on sys.path (``python -m pytest`` would: the tests would then import the source
    tree and miss a file the package fails to install). Skipped where segparam is not installed
    or installed editable, as in development (``PYTHONPATH=$PWD``)."""
    # Metadata found through the repository itself (the segparam.egg-info a build leaves) is
    # not an installation.
    repo = PYPROJECT.parent
    elsewhere = [p for p in sys.path if Path(p or ".").resolve() != repo]
    dist = next(iter(md.distributions(name="segparam", path=elsewhere)), None)
    if dist is None:
        pytest.skip("segparam is not installed")
    direct = json.loads(dist.read_text("direct_url.json") or "{}")
    if direct.get("dir_info", {}).get("editable", False):
        pytest.skip("segparam is installed editable")
    installed = Path(dist.locate_file("segparam/__init__.py")).resolve()
    assert Path(segparam.__file__).resolve() == installed, (
        f"the tests import {segparam.__file__}, not the installed {installed}: run `pytest`, "
        "not `python -m pytest`, from the repository"
    )


def test_the_readme_test_command_is_what_ci_runs():
    ci = (PYPROJECT.parent / ".ci" / "run").read_text(encoding="utf-8").strip().splitlines()
    command = ci[-1]  # .ci/run ends with it, after making and activating a fresh venv
    assert command.startswith("pip install") and "pytest" in command
    readme = (PYPROJECT.parent / "README.md").read_text(encoding="utf-8")
    assert f". .venv/bin/activate && {command}\n" in readme
