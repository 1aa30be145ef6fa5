"""requirements.lock: the exact versions `make figures` / `make test` install.

It must agree with the package versions every committed run's manifest records (the
results were made with it), satisfy pyproject.toml's ranges (which stay open for people who
use the library in their own environment), and, in the environment the Makefile built,
be what is installed (elsewhere the declared ranges must hold).
"""

from __future__ import annotations

import importlib.metadata as md
import json
import re
import sys
import tomllib
from pathlib import Path

import pytest
from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parent.parent
LOCK = ROOT / "requirements.lock"
#: Installed by the venv itself, not by the lock.
TOOLING = {"pip", "setuptools", "wheel", "repro"}


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _lock() -> dict[str, str]:
    pins = {}
    for line in LOCK.read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        name, sep, version = line.partition("==")
        assert sep and version, f"requirements.lock: {line!r} is not an exact pin"
        pins[_norm(name)] = version
    return pins


def _manifests() -> list[Path]:
    return sorted((ROOT / "results").glob("*/*/manifest.json"))


def test_lock_pins_every_package_exactly() -> None:
    pins = _lock()
    assert len(pins) > 20 and "numpy" in pins and "pybullet" in pins


@pytest.mark.parametrize("manifest", _manifests(), ids=lambda p: f"{p.parent.parent.name}/"
                         f"{p.parent.name}")
def test_committed_runs_were_made_with_the_locked_versions(manifest: Path) -> None:
    pins = _lock()
    recorded = json.loads(manifest.read_text())["packages"]
    differ = {k: (v, pins.get(_norm(k), "not locked")) for k, v in recorded.items()
              if pins.get(_norm(k)) != v}
    assert not differ, (f"{manifest.parent}: recorded vs locked {differ}; remake the run or "
                        "the lock")


def test_lock_satisfies_the_ranges_of_pyproject() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    reqs = [Requirement(r) for r in project["dependencies"]
            + project["optional-dependencies"]["dev"]]
    pins = _lock()
    for r in reqs:
        name = _norm(r.name)
        assert name in pins, f"{r.name} is a dependency but not in requirements.lock"
        assert r.specifier.contains(pins[name], prereleases=True), (
            f"requirements.lock pins {r.name}=={pins[name]} outside pyproject's {r}")


def test_no_dependency_is_declared_that_nothing_imports() -> None:
    """Every direct dependency is imported somewhere (distribution -> module names)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    modules = {"pin": "pinocchio", "python-fcl": "fcl", "opencv-python-headless": "cv2",
               "imageio": "imageio"}
    sources = "\n".join(p.read_text() for d in ("repro", "experiments", "tests")
                        for p in (ROOT / d).rglob("*.py"))
    for r in project["dependencies"] + project["optional-dependencies"]["dev"]:
        name = Requirement(r).name
        if name in ("pytest", "ruff", "mypy"):
            continue  # tools, run by the Makefile
        mod = modules.get(name, name.replace("-", "_"))
        assert re.search(rf"^\s*(import|from) {mod}\b", sources, re.M), (
            f"{name} is declared in pyproject.toml but nothing imports {mod}")


def test_the_environment_holds_the_locked_or_declared_versions() -> None:
    """In the venv `make` built (its stamp file), every installed distribution is locked at
    the installed version: nothing was resolved outside the lock. In a library user's own
    environment, every declared dependency is installed within pyproject.toml's range."""
    if (Path(sys.prefix) / ".installed").is_file():
        pins = _lock()
        installed = {_norm(d.metadata["Name"]): d.version for d in md.distributions()}
        off = {k: (v, pins.get(k, "not locked")) for k, v in installed.items()
               if k not in TOOLING and pins.get(k) != v}
        assert not off, f"installed vs requirements.lock: {off}"
        return
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    for r in map(Requirement, project["dependencies"]):
        try:
            version = md.version(r.name)
        except md.PackageNotFoundError:
            pytest.fail(f"{r.name} is a dependency of repro but is not installed")
        assert r.specifier.contains(version, prereleases=True), (
            f"{r.name}=={version} is outside pyproject's {r}")
