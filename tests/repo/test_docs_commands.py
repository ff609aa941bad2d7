"""Docs cannot drift: every shell command in the README and the user guides is parsed by the CLI it names.

The commands come from the ```bash (sh, shell, console) blocks of README.md, every docs/*.md present (not the
history under docs/research or the records under docs/results) and the model cards (models/*/README.md); the
other commands of those blocks (pip, scripts, udev, ROS 2, torchrun) are in test_docs_every_command.py's table.
For each `lerobot-*`, `blindgrasp-*` and `python -m lerobot...` command:
- its own parser reads the whole command line, in-process: the entry point runs with that argv until draccus has
  built its config (LeRobot's `parser.wrap`, `draccus.wrap` and this package's `parse_config` all end in
  `draccus.parse`), then stops. So every flag must exist on the config it reaches, `include` files must load and
  their values must pass the configs' own checks;
- `--help` of each program prints its help and exits 0;
- where an emulator or a recorded file can serve it, the command runs whole (`real_report` on an eval_info.json
  recorded by lerobot-eval on the emulated gripper; `lerobot-find-port` up to its first question). The guide's
  lerobot-record and lerobot-teleoperate lines run whole on the emulators in test_glove_training.py; its
  calibrations (gripper, glove, `blindgrasp-calibrate-force`), `blindgrasp-rollout`, `lerobot-eval` of the real env
  with its report, and the force board's build and sim lines in test_docs_commands_run.py.
Placeholders (`<user>`, `<checkpoint>` ...) become concrete values; a `--policy.path` that does not exist becomes the
shipped student, since LeRobot reads a policy's config at parse time. Nothing trains, records or moves.
"""

from __future__ import annotations

import contextlib
import importlib.metadata
import io
import os
import runpy
import sys
from pathlib import Path

import draccus
import draccus.argparsing
import pytest
from doc_commands import ALL, ROOT, SHIPPED_STUDENT, DocCommand

# Written by lerobot-eval --env.type=blindgrasp_real of models/student_cpu on the emulated gripper (tasks
# cylinder_a_medium,wine_glass, 2 episodes each, --env.success_mode=force, --env.episode_s=1.0: too short to hold an
# object for 1 s, so 0/4), video paths made relative; the command is test_hw_cli.py's lerobot-eval test.
RECORDED_EVAL_INFO = ROOT / "tests" / "data" / "real_eval_info.json"


class _Parsed(BaseException):  # BaseException: no `except Exception` of a CLI swallows it
    def __init__(self, cfg):
        self.cfg = cfg


@pytest.fixture(scope="module")
def sandbox(tmp_path_factory):
    """A working folder that sees the repository's files (configs, models) but keeps anything a parser writes."""
    box = tmp_path_factory.mktemp("docs_cwd")
    for entry in ROOT.iterdir():
        if not entry.name.startswith(".") and entry.name not in ("outputs", "runs"):
            (box / entry.name).symlink_to(entry)
    return box


OFFLINE_ENV = {
    "HF_HUB_OFFLINE": "1",
    "HF_DATASETS_OFFLINE": "1",
    "OMP_WAIT_POLICY": "PASSIVE",
    "WANDB_MODE": "disabled",
}  # OMP_WAIT_POLICY set: no command restarts itself (sleeping_openmp_threads)


@contextlib.contextmanager
def offline_in(box: Path, home: Path):
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(box)
        env = {
            **OFFLINE_ENV,
            "HF_HOME": str(home / "hf"),
            "HF_LEROBOT_HOME": str(home / "hf" / "lerobot"),
            "HF_LEROBOT_CALIBRATION": str(home / "calibration"),
        }
        for k, v in env.items():
            mp.setenv(k, v)
        yield mp


@pytest.fixture
def offline(sandbox, tmp_path):
    with offline_in(sandbox, tmp_path) as mp:
        yield mp


@pytest.fixture(scope="module")
def parsed(sandbox, tmp_path_factory) -> dict[DocCommand, tuple]:
    """Every command parsed once: (config or None, exit code, output)."""
    out = {}
    with offline_in(sandbox, tmp_path_factory.mktemp("home")) as mp:
        for cmd in ALL:
            if cmd.argv[0] != "lerobot-find-port":
                with mp.context() as inner:
                    out[cmd] = run_in_process(_with_existing_policy(cmd.argv), inner, stop_at_parse=True)
    return out


def _with_existing_policy(argv: tuple[str, ...]) -> list[str]:
    out = []
    for a in argv:
        if a.startswith("--policy.path=") and not Path(a.split("=", 1)[1]).exists():
            a = f"--policy.path={SHIPPED_STUDENT}"
        out.append(a)
    return out


def run_in_process(argv: list[str], monkeypatch, stop_at_parse: bool):
    """Run the command's entry point in this process; returns (config or None, exit code, output)."""
    orig = draccus.argparsing.parse
    depth = [0]

    def recording_parse(*args, **kwargs):
        # Only the command's own config stops the run: building it may parse others (lerobot-eval's and the
        # rollout's __post_init__ read the policy's config from --policy.path through draccus.parse).
        depth[0] += 1
        try:
            cfg = orig(*args, **kwargs)
        finally:
            depth[0] -= 1
        if depth[0]:
            return cfg
        raise _Parsed(cfg)

    # With the variable unset, a command restarts itself with it (`cli.sleeping_openmp_threads`: os.execv), which
    # here would replace the test process.
    monkeypatch.setenv("OMP_WAIT_POLICY", os.environ.get("OMP_WAIT_POLICY", "PASSIVE"))
    if stop_at_parse:
        monkeypatch.setattr(draccus, "parse", recording_parse)
        monkeypatch.setattr(draccus.argparsing, "parse", recording_parse)
    if argv[0] == "python":  # `python -m X`: X.main() reads sys.argv, as under runpy
        module = importlib.import_module(argv[2])
        prog = argv[2]
        run = module.main if hasattr(module, "main") else (
            lambda: runpy.run_module(argv[2], run_name="__main__", alter_sys=True))  # fmt: skip
    else:
        [ep] = [e for e in importlib.metadata.entry_points(group="console_scripts") if e.name == argv[0]]
        prog, run = argv[0], ep.load()
    monkeypatch.setattr(sys, "argv", [prog, *argv[3 if argv[0] == "python" else 1 :]])
    buf = io.StringIO()
    cfg, code = None, 0
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
        try:
            run()
        except _Parsed as p:
            cfg = p.cfg
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
            if e.code not in (None, 0) and not isinstance(e.code, int):
                buf.write(str(e.code))
    return cfg, code, buf.getvalue()


def test_the_docs_have_commands_to_check():
    docs = {c.doc for c in ALL}
    assert {"docs/hardware.md", "docs/bringup.md"} <= docs, docs
    programs = {c.program for c in ALL}
    assert {"lerobot-calibrate", "lerobot-record", "lerobot-eval", "blindgrasp-rollout"} <= programs, programs


@pytest.mark.parametrize("cmd", [c for c in ALL if c.argv[0] != "lerobot-find-port"], ids=str)
def test_each_command_parses_with_its_flags(cmd, parsed):
    from lerobot.configs.policies import PreTrainedConfig

    cfg, code, out = parsed[cmd]
    assert cfg is not None, f"{cmd}\nexit {code} before its config was built:\n{out[-3000:]}"
    assert not isinstance(cfg, PreTrainedConfig), f"{cmd}: stopped at the policy's config, not the command's"


@pytest.mark.parametrize("program", sorted({c.program for c in ALL} - {"lerobot-find-port"}))
def test_each_program_has_help(program, offline, monkeypatch):
    argv = program.split() + ["--help"]
    _, code, out = run_in_process(argv, monkeypatch, stop_at_parse=False)
    assert code == 0 and "usage" in out.lower(), out[-2000:]


def _robot_id(cfg) -> str | None:
    robot = getattr(cfg, "robot", None) or getattr(getattr(cfg, "env", None), "robot", None)
    return getattr(robot, "id", None) if getattr(robot, "type", None) == "blindgrasp_gripper" else None


def test_every_gripper_command_uses_the_calibrated_id(parsed):
    """The id picks the calibration file: calibrate, record, deploy and eval of one guide name one gripper."""
    for doc in sorted({c.doc for c in parsed}):
        ids: dict[str, list[str]] = {}
        for cmd, (cfg, _, _) in parsed.items():
            if cmd.doc == doc and (rid := _robot_id(cfg)) is not None:
                ids.setdefault(rid, []).append(str(cmd))
        assert len(ids) <= 1, f"{doc}: gripper commands name different --robot.id values: {ids}"
        assert set(ids) != {"blindgrasp_gripper"}, f"{doc}: pass --robot.id (the yaml's default id) explicitly"


def test_real_report_runs_on_a_recorded_eval(offline, monkeypatch):
    reports = [c for c in ALL if c.program == "python -m lerobot_blindgrasp.envs.real_report"]
    assert reports
    for cmd in reports:
        argv = [a if not a.startswith("--eval_info=") else f"--eval_info={RECORDED_EVAL_INFO}" for a in cmd.argv]
        _, code, out = run_in_process(argv, monkeypatch, stop_at_parse=False)
        assert code == 0 and "| **overall** | 4 |" in out and "95 % interval" in out, f"{cmd}\n{out}"


def test_lerobot_find_port_runs_to_its_question(offline, monkeypatch):
    if not any(c.argv[0] == "lerobot-find-port" for c in ALL):
        pytest.skip("no guide names lerobot-find-port")
    monkeypatch.setattr("builtins.input", lambda prompt="": "")  # ENTER at once: no port went away
    buf = io.StringIO()
    from lerobot.scripts import lerobot_find_port

    with contextlib.redirect_stdout(buf), pytest.raises(OSError, match="Could not detect the port"):
        lerobot_find_port.main()
    assert "Remove the USB cable from your MotorsBus" in buf.getvalue()


def test_glove_training_reads_a_folder_the_docs_record_into(parsed):
    """`blindgrasp-train-glove --glove=[...]` names folders a documented lerobot-record writes (--dataset.root)."""
    from lerobot_blindgrasp.pipeline.glove_train import GloveTrainConfig

    recorded = {Path(cfg.dataset.root) for cfg, _, _ in parsed.values()
                if type(cfg).__name__ == "RecordConfig" and cfg.dataset.root is not None}  # fmt: skip
    for cmd, (cfg, _, _) in parsed.items():
        if isinstance(cfg, GloveTrainConfig):
            unknown = [str(g) for g in cfg.glove if Path(g) not in recorded]
            assert not unknown, f"{cmd}: no documented lerobot-record writes {unknown} (--dataset.root)"
