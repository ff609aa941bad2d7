"""The force board's build without its toolchain: the sources ship inside the package, and a missing tool is named
by its Debian package (the tests that need the toolchain, tests/hardware/test_force_board_sim.py, skip with that list)."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from lerobot_blindgrasp.hardware.force_board import build

ROOT = Path(__file__).resolve().parents[2]


def test_the_sources_ship_as_package_data():
    patterns = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    shipped = patterns["lerobot_blindgrasp.hardware.force_board"]
    for source in ("firmware/force_board.c", "firmware/Makefile", "simavr/hx711_sim.c"):
        assert (build.HERE / source).is_file()
        assert any(Path(source).match(p) for p in shipped), (source, shipped)


def test_a_missing_toolchain_is_named_by_its_debian_packages(monkeypatch, tmp_path):
    monkeypatch.setattr(build.shutil, "which", lambda name: None)
    monkeypatch.setattr(build, "SIMAVR_INCLUDE", tmp_path / "nowhere")
    assert {"gcc-avr", "make", "gcc", "libsimavr-dev"} <= set(build.missing_packages())
    with pytest.raises(build.BuildError, match=r"apt-get install make gcc-avr"):
        build.build_firmware(tmp_path)
    with pytest.raises(build.BuildError, match=r"apt-get install gcc libsimavr-dev"):
        build.build_simulator(tmp_path)
