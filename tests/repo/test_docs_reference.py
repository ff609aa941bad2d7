"""docs/reference.md cannot drift: its generated tables equal what scripts/docs_reference.py makes from
pyproject.toml and the preset registry today, and every console script and every preset appears in it."""

from __future__ import annotations

import importlib
import importlib.util
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "reference.md"


def _generator():
    spec = importlib.util.spec_from_file_location("docs_reference", ROOT / "scripts" / "docs_reference.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(spec.name, module)  # its dataclass resolves its module through sys.modules
    spec.loader.exec_module(module)
    return module


def test_the_generated_tables_are_current():
    gen = _generator()
    assert gen.rendered(DOC.read_text(encoding="utf-8")) == DOC.read_text(encoding="utf-8"), (
        "docs/reference.md is out of date: run python scripts/docs_reference.py"
    )


def test_every_console_script_and_preset_is_in_the_reference():
    from lerobot_blindgrasp import presets
    from lerobot_blindgrasp.presets import glove, teacher

    text = DOC.read_text(encoding="utf-8")
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    names = [*scripts, *presets.PRESETS, *teacher.TEACHER_PRESETS, *presets.TABLE_V, *glove.GLOVE_PRESETS]
    missing = [n for n in names if f"| `{n}` |" not in text]
    assert not missing, f"not in docs/reference.md: {missing}"


def test_every_command_names_the_config_class_it_parses():
    gen = _generator()
    for name, target in gen.console_scripts().items():
        module, func = target.split(":")
        cls = gen.config_class(module, func)
        assert cls, f"{name}: no config class found in {module}.{func}"
        owner = importlib.import_module(module) if "." not in cls else None
        if owner is not None:
            assert hasattr(owner, cls), (name, cls)
