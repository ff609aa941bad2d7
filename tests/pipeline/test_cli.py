"""One CLI style: every command is a draccus dataclass config with named flags, and `--help` lists them."""

from __future__ import annotations

import importlib
import importlib.util
import sys
import tomllib
from pathlib import Path

import pytest

from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.teacher.train import TrainTeacherConfig

ROOT = Path(__file__).resolve().parents[2]
# Commands run as `python -m MODULE` (no console script): what README.md and the docs show.
MODULE_COMMANDS = (
    "lerobot_blindgrasp.results.compare",
    "lab.table_v",
    "lerobot_blindgrasp.envs.real_report",
)
# The lab's commands (`python -m lab.<tool>` from a clone's root): every lab module that runs as a command, and the
# benchmarks' package (its `__main__.py`).
LAB_COMMANDS = (
    "lab.bench",
    *sorted(
        ".".join(p.relative_to(ROOT).with_suffix("").parts)
        for p in (ROOT / "lab").rglob("*.py")
        if '__name__ == "__main__"' in p.read_text(encoding="utf-8")
    ),
)


def _console_scripts() -> dict[str, str]:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]


def test_draccus_spellings_and_yaml_config(tmp_path):
    cfg = parse_config(TrainTeacherConfig, ["--output_dir=runs/t", "--preset=quick", "--no_incentive=true"])
    assert cfg.output_dir == Path("runs/t") and cfg.preset == "quick" and cfg.no_incentive and cfg.export
    cfg = parse_config(TrainTeacherConfig, ["--output_dir", "runs/t", "--num_envs", "36"])  # `--flag value` too
    assert cfg.num_envs == 36
    yaml = tmp_path / "t.yaml"
    yaml.write_text("output_dir: runs/y\npreset: quick\niterations: 7\nexport: false\n")
    cfg = parse_config(TrainTeacherConfig, ["--config_path", str(yaml), "--iterations=9"])
    assert cfg.output_dir == Path("runs/y") and cfg.iterations == 9 and not cfg.export  # flags override the file


def test_bad_input_is_one_clear_line():
    with pytest.raises(SystemExit, match=r"unknown preset 'bogus' \(teacher\); choose from .*cpu_bc_capsule"):
        parse_config(TrainTeacherConfig, ["--preset=bogus", "--output_dir=x"])
    with pytest.raises(SystemExit, match="--output_dir is required"):
        parse_config(TrainTeacherConfig, ["--preset=quick"])


@pytest.mark.parametrize(
    "argv",
    [
        ["--preset", "quick", "--output-dir", "runs/t"],  # dashes
        ["--preset=quick", "--output_dir=runs/t", "--no-export"],  # argparse's bare --no-X
        ["--preset=quick", "--output_dir=runs/t", "--export"],  # a boolean takes its value
        ["runs/t", "--preset=quick"],  # positional
    ],
)
def test_other_spellings_are_refused(argv, capsys):
    with pytest.raises(SystemExit):
        parse_config(TrainTeacherConfig, argv)


def test_every_command_has_help(monkeypatch, capsys):
    """`--help` of every console script in pyproject.toml and every `python -m` command, the lab's included, lists
    its flags."""
    monkeypatch.setenv("OMP_WAIT_POLICY", "PASSIVE")  # a command that would set it leaves this process alone
    targets = [(name, *target.split(":")) for name, target in _console_scripts().items()]
    targets += [(module, module, "main") for module in (*MODULE_COMMANDS, *LAB_COMMANDS)]
    for name, module, func in targets:
        main = getattr(importlib.import_module(module), func)
        # LeRobot's own parser (the rollout reuses lerobot-rollout's config and parser) reads sys.argv.
        monkeypatch.setattr(sys, "argv", [name, "--help"])
        with pytest.raises(SystemExit) as e:
            main() if module.endswith(".rollout") else main(["--help"])
        out = capsys.readouterr().out
        assert e.value.code in (0, None), name
        assert "usage:" in out and "--" in out.split("usage:", 1)[1], name


@pytest.mark.parametrize("script", sorted((ROOT / "scripts").glob("*.py")), ids=lambda p: p.name)
def test_every_script_has_help(script, monkeypatch, capsys):
    spec = importlib.util.spec_from_file_location(f"scripts_{script.stem}", script)
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, spec.name, module)  # draccus resolves the config's annotations through it
    spec.loader.exec_module(module)
    main = module.main
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0 and "usage:" in capsys.readouterr().out


def test_the_guides_lab_commands_parse_as_written(monkeypatch):
    """Each `python -m lab...` line of the README and the guides parses with its tool's own config, flag by flag."""
    import re
    import shlex

    spec = importlib.util.spec_from_file_location("docs_reference", ROOT / "scripts" / "docs_reference.py")
    gen = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, spec.name, gen)  # its dataclass resolves its module through sys.modules
    spec.loader.exec_module(gen)
    found = []
    for doc in (ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))):
        for module, args in re.findall(
            r"^python -m (lab[\w.]*) ([^\\\n]*)$", doc.read_text(encoding="utf-8"), re.M
        ):
            argv = shlex.split(args)
            if module == "lab.bench":  # each benchmark registers its --bench.type when imported
                bench = importlib.import_module(module)
                for name in bench._modules(argv):
                    importlib.import_module(f"lab.bench.{name}_bench")
            cls = getattr(importlib.import_module(module), gen.config_class(module))
            parse_config(cls, argv)
            found.append(module)
    assert {"lab.bench", "lab.diagnosis.progress"} <= set(found), found


def test_the_benchmark_is_picked_by_its_type():
    from lab.bench import BenchCommand
    from lab.bench.sim_bench import BenchSimConfig

    cfg = parse_config(
        BenchCommand, ["--bench.type=sim", "--bench.num_envs=36", "--bench.threads=[1,2]", "--bench.json=true"]
    ).bench
    assert isinstance(cfg, BenchSimConfig) and (cfg.num_envs, cfg.threads, cfg.json) == (36, [1, 2], True)
    with pytest.raises(SystemExit):
        parse_config(BenchCommand, ["sim", "--num_envs=36"])


def test_the_pipelines_command_lines_parse_with_each_commands_config(tmp_path):
    """Every blindgrasp-* line that `blindgrasp-pipeline --print_commands` (and so scripts/paper_recipe.sh) prints
    parses with its command's own config, in the one spelling."""
    from lerobot_blindgrasp import presets
    from lerobot_blindgrasp.demos.config import CollectConfig
    from lerobot_blindgrasp.pipeline import recipe
    from lerobot_blindgrasp.teacher.evaluate import EvalTeacherConfig

    configs = {
        "blindgrasp-train-teacher": TrainTeacherConfig,
        "blindgrasp-eval-teacher": EvalTeacherConfig,
        "blindgrasp-collect-demos": CollectConfig,
    }
    seen = set()
    for stage in ("teachers", "teacher_evals", "demos"):
        for cmd in recipe.table_v(presets.get("smoke"), tmp_path, stage):
            if cmd[0] in configs:
                parse_config(configs[cmd[0]], cmd[1:])
                seen.add(cmd[0])
    assert seen == set(configs)
