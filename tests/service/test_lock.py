"""The checked-in lock pins every dependency pyproject.toml names, and this environment was installed from it."""

from __future__ import annotations

import re
import tomllib
from importlib import metadata

from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

from tests.service.conftest import ROOT

LOCK = ROOT / "requirements.lock"
PIN = re.compile(r"^([A-Za-z0-9][A-Za-z0-9._-]*)==([^\s;#]+)$")


def locked() -> dict[str, str]:
    out: dict[str, str] = {}
    for line in LOCK.read_text().splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        m = PIN.match(line)
        assert m, f"requirements.lock: not an exact pin: {line!r}"
        name = canonicalize_name(m.group(1))
        assert name not in out, f"requirements.lock pins {name} twice"
        out[name] = m.group(2)
    return out


def declared() -> list[Requirement]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    reqs = [Requirement(r) for r in project["dependencies"]]
    for extra in project["optional-dependencies"].values():
        reqs += [Requirement(r) for r in extra]
    return reqs


def test_every_pyproject_dependency_is_pinned_within_its_range() -> None:
    pins = locked()
    for req in declared():
        name = canonicalize_name(req.name)
        assert name in pins, f"{req} is not in requirements.lock: run `make lock`"
        assert req.specifier.contains(Version(pins[name]), prereleases=True), (
            f"requirements.lock has {name}=={pins[name]}, outside {req}: run `make lock`")
    assert "pip" in pins  # the venv bootstrap upgrades pip to the locked version too


def test_this_environment_has_the_locked_versions() -> None:
    """`make test` installs with -c requirements.lock: every direct dependency installed here is the locked one."""
    pins = locked()
    for req in declared():
        name = canonicalize_name(req.name)
        try:
            have = metadata.version(req.name)
        except metadata.PackageNotFoundError:  # an extra this environment did not install (bench)
            continue
        assert Version(have) == Version(pins[name]), f"{name} {have} installed, {pins[name]} locked"


def test_installs_use_the_lock() -> None:
    make = (ROOT / "Makefile").read_text()
    assert "PIP := $(BIN)/python -m pip install -q -c $(LOCK)" in make and "LOCK := requirements.lock" in make
    assert "pip install -q -e" not in make.replace("$(LOCK_VENV)", "")  # every venv install goes through $(PIP)
    assert "-c requirements.lock" in (ROOT / "Dockerfile").read_text()
