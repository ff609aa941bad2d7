"""Every command in a fenced shell block of README.md, docs/*.md (not docs/research/, the history) and the model
cards (models/*/README.md) is accounted for: run, parsed, checked, or listed as not runnable here with the reason.

`RULES` is the one table: each rule matches a command by its first words (shell wildcards, so `lerobot-*` is every
LeRobot and package console script) and says what happens to it here. A command that matches no rule fails
`test_every_command_is_in_the_table`, so a new doc line is either checked or explicitly excused. Every line also goes
through `bash -n` (the shell's own parser: quoting, pipes, `$(...)`). `sudo` in front of a command marks it
root-only, whatever the rule says, and its command is still checked.

What "parsed" means for our programs (`lerobot-*`, `blindgrasp-*`, `python -m lerobot_blindgrasp...`) is
`test_docs_commands.py` (draccus parses every flag against the real config) and `test_docs_commands_run.py` (the
hardware lines run whole on the emulators); the other kinds are checked in this file.
"""

from __future__ import annotations

import fnmatch
import re
import shlex
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest
from doc_commands import ROOT, concrete, shell_blocks
from packaging.requirements import Requirement
from test_docs_commands import run_in_process

PARSED = "parsed by its own CLI parser (test_docs_commands.py)"
PIP = "checked: each requirement parses and names this distribution, its extras exist in pyproject.toml"
SCRIPT = "checked: the script exists and `bash -n` parses it"
BUILD = "run by tests/repo/test_wheel.py (python -m build, without isolation: the isolated build downloads its backend)"
WHEEL = "checked: the wheel's file name is the one `python -m build` makes from pyproject.toml"
ROOT_ONLY = "not runnable here: needs root (sudo) on a PC with the hardware; its files are checked to exist"
ROS = "not runnable here: ROS 2 and the MANUS workspace are not installed (the glove's own machine)"
GPU = "not runnable here: several GPUs; the program it starts is parsed with these flags"
SHELL = "runs: a shell builtin or coreutils, checked by `bash -n`"
LAB = "parsed: the lab tool's own draccus parser reads the flags (lab/ is the repository's, not the package's)"
GIT_PROGRAM = "checked: `bash -n`, and every commit it names exists in this repository (the tags' targets)"
BRIDGE = "parsed by the copied glove bridge's own argparse (`manus_bridge.parse_args`); `--help` runs"
BRIDGE_FILE = ROOT / "lerobot_blindgrasp" / "teleoperators" / "manus_glove" / "manus_bridge.py"

# (first words, what happens to the command here). First match wins; wildcards as in fnmatch.
RULES: list[tuple[tuple[str, ...], str]] = [
    (("lerobot-*",), PARSED),
    (("blindgrasp-*",), PARSED),
    (("python", "-m", "lerobot_blindgrasp*"), PARSED),
    (("python", "-m", "lerobot.*"), PARSED),
    (("python", "-m", "lab.*"), LAB),
    (("python", "-m", "build"), BUILD),
    (("python", "manus_bridge.py"), BRIDGE),
    (("pip", "install", "dist/*.whl"), WHEEL),
    (("pip", "install"), PIP),
    (("bash", "scripts/*.sh"), SCRIPT),
    (("cp", "robot_configs/*"), ROOT_ONLY),
    (("udevadm",), ROOT_ONLY),
    (("usermod",), ROOT_ONLY),
    (("tee", "/sys/*"), ROOT_ONLY),
    (("tee", "-a", "/etc/security/limits.d/*"), ROOT_ONLY),
    (("ros2",), ROS),
    (("source", "/opt/ros/*"), ROS),
    (("source", "*/install/setup.bash"), ROS),
    (("torchrun",), GPU),
    (("echo",), SHELL),
    (("<program>", "while"), GIT_PROGRAM),
]
SEPARATORS = {"&&", "||", ";", "|", "&"}
WRAPPERS = {"nohup", "nice", "env", "time"}


def doc_files() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted(ROOT.glob("models/*/README.md"))]


@dataclass(frozen=True)
class Command:
    doc: str
    line: int
    words: tuple[str, ...]
    sudo: bool
    text: str  # the whole logical line it came from

    def __str__(self) -> str:
        return f"{self.doc}:{self.line}: {'sudo ' if self.sudo else ''}{shlex.join(self.words)}"


def logical_lines(doc: Path):
    """(line number, text) of each command line of the doc's shell blocks, continuation lines joined; a block that
    is one shell program (a here-document) is one text."""
    for start, block in shell_blocks(doc.read_text()):
        if any("<<" in line for line in block):
            yield start, "\n".join(block)
            continue
        logical, first = "", start
        for k, raw in enumerate(block):
            text = raw[2:] if raw.startswith("$ ") else raw
            if not logical:
                first = start + k
            more = text.rstrip().endswith("\\")
            logical += text.rstrip()[:-1] + " " if more else text
            if not more:
                if logical.strip() and not logical.lstrip().startswith("#"):
                    yield first, logical
                logical = ""


def commands() -> list[Command]:
    out = []
    for doc in doc_files():
        for line, text in logical_lines(doc):
            if "\n" in text:  # a program: one command, named by its first word
                out.append(Command(str(doc.relative_to(ROOT)), line, ("<program>", text.split()[0]), False, text))
                continue
            lexer = shlex.shlex(concrete(text), posix=True, punctuation_chars=";&|")
            lexer.whitespace_split, lexer.commenters = True, "#"
            cmd: list[str] = []
            for w in [*lexer, ";"]:
                if w not in SEPARATORS:
                    cmd.append(w)
                    continue
                sudo = False
                while cmd and (cmd[0] in WRAPPERS | {"sudo"} or re.match(r"^\w+=", cmd[0])):
                    sudo |= cmd.pop(0) == "sudo"
                if cmd:
                    out.append(Command(str(doc.relative_to(ROOT)), line, tuple(cmd), sudo, text))
                cmd = []
    return out


def rule_of(cmd: Command) -> str | None:
    words = ["python" if re.match(r"^(\S*/)?python3?$", w) else w for w in cmd.words]
    for prefix, kind in RULES:
        if len(words) >= len(prefix) and all(fnmatch.fnmatchcase(w, p) for w, p in zip(words, prefix)):
            return kind
    return None


ALL = commands()
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]


def test_the_docs_and_the_model_cards_are_read():
    docs = {c.doc for c in ALL}
    assert {"README.md", "docs/bringup.md", "models/student_cpu/README.md"} <= docs, docs
    assert not any(d.startswith("docs/research/") for d in docs)


@pytest.mark.parametrize("cmd", ALL, ids=str)
def test_every_command_is_in_the_table(cmd):
    kind = rule_of(cmd)
    assert kind is not None, f"{cmd}: no rule in RULES says how this command is checked or why it cannot run here"
    if cmd.sudo:
        assert kind in (ROOT_ONLY, PIP), f"{cmd}: runs under sudo, so it belongs to the root-only rules"


@pytest.mark.parametrize("text", sorted({(c.doc, c.line, c.text) for c in ALL}), ids=lambda t: f"{t[0]}:{t[1]}")
def test_every_line_is_valid_shell(text):
    res = subprocess.run(["bash", "-n"], input=concrete(text[2]), capture_output=True, text=True)
    assert res.returncode == 0, f"{text[0]}:{text[1]}: {res.stderr}"


def _of(kind: str) -> list[Command]:
    return [c for c in ALL if rule_of(c) == kind]


@pytest.mark.parametrize("cmd", _of(PIP), ids=str)
def test_pip_install_lines_name_this_distribution_and_its_extras(cmd):
    extras = set(PYPROJECT["optional-dependencies"])
    targets = [w for w in cmd.words[2:] if not w.startswith("-")]
    assert targets, cmd
    for target in targets:
        if target.startswith("."):  # a clone: `.` or `.[extra,...]`
            named = re.fullmatch(r"\.(?:\[([\w,-]+)\])?", target)
            assert named, f"{cmd}: {target!r}"
            assert set(filter(None, (named.group(1) or "").split(","))) <= extras, f"{cmd}: extras {extras}"
        else:
            req = Requirement(target)
            assert req.name == PYPROJECT["name"] and req.extras <= extras, f"{cmd}: {req}"


@pytest.mark.parametrize("cmd", _of(WHEEL), ids=str)
def test_the_documented_wheel_is_the_one_build_makes(cmd):
    wheel = f"dist/{PYPROJECT['name']}-{PYPROJECT['version']}-py3-none-any.whl"
    assert cmd.words[2] == wheel, cmd
    assert any(c.words[:3] == ("python", "-m", "build") and "dist" in c.words for c in ALL)


@pytest.mark.parametrize("cmd", _of(SCRIPT), ids=str)
def test_documented_scripts_exist_and_parse(cmd):
    script = ROOT / cmd.words[1]
    assert script.is_file(), cmd
    assert subprocess.run(["bash", "-n", str(script)], capture_output=True).returncode == 0, cmd


@pytest.mark.parametrize("cmd", _of(ROOT_ONLY), ids=str)
def test_root_only_lines_name_files_that_exist(cmd):
    assert cmd.sudo, f"{cmd}: a root-only command without sudo"
    for w in cmd.words[1:]:
        if w.startswith("robot_configs/"):
            assert (ROOT / w).exists(), cmd
    if cmd.words[0] == "usermod":
        assert cmd.words[1:3] == ("-aG", "dialout"), cmd  # the group the udev rules give the ports


@pytest.mark.parametrize("cmd", _of(GPU), ids=str)
def test_torchrun_lines_start_a_program_whose_flags_parse(cmd, monkeypatch, tmp_path):
    """torchrun's own options, then `"$(which PROGRAM)"` and PROGRAM's flags: those flags parse against its config."""
    rest = list(cmd.words[1:])
    while rest and rest[0].startswith("--"):
        rest.pop(0)
    program = re.fullmatch(r"\$\(which ([\w-]+)\)", rest[0])
    assert program, f'{cmd}: torchrun should start `"$(which PROGRAM)"`'
    monkeypatch.chdir(tmp_path)
    cfg, code, out = run_in_process([program.group(1), *rest[1:]], monkeypatch, stop_at_parse=True)
    assert cfg is not None, f"{cmd}\nexit {code}:\n{out[-2000:]}"


def test_no_command_hides_in_a_block_of_another_language():
    """A command in a ```text (or untagged) block would escape the table: every runnable line is in a shell block."""
    scripts = tuple(PYPROJECT["scripts"])
    starts = re.compile(
        rf"^\s*(\$ )?({'|'.join(map(re.escape, scripts))}|lerobot-[\w-]+|pip install|python3? -m )\b"
    )
    hidden = []
    for doc in doc_files():
        lang = None
        for i, line in enumerate(doc.read_text().splitlines(), 1):
            if fence := re.match(r"^\s*```+\s*([\w-]*)", line):
                lang = None if lang is not None else fence.group(1).lower()
            elif lang is not None and lang not in {"bash", "sh", "shell", "console"} and starts.match(line):
                hidden.append(f"{doc.relative_to(ROOT)}:{i} ({lang or 'untagged'}): {line.strip()}")
    assert not hidden, hidden


@pytest.mark.parametrize("cmd", _of(BRIDGE), ids=str)
def test_glove_bridge_lines_parse_with_the_bridges_own_parser(cmd):
    """The bridge is one file a lab copies to the glove's machine and runs with its python3: run it the same way."""
    if "--help" in cmd.words:
        res = subprocess.run([sys.executable, str(BRIDGE_FILE), "--help"], capture_output=True, text=True)
        assert res.returncode == 0 and "usage" in res.stdout.lower(), res.stderr
        return
    from lerobot_blindgrasp.teleoperators.manus_glove import manus_bridge

    assert manus_bridge.parse_args(list(cmd.words[2:])) is not None, cmd


@pytest.mark.parametrize("cmd", _of(GIT_PROGRAM), ids=str)
def test_git_programs_name_commits_of_this_history(cmd):
    commits = re.findall(r"\b[0-9a-f]{40}\b", cmd.text)
    assert commits and "git " in cmd.text, cmd
    if not (ROOT / ".git").exists():
        pytest.skip("not a git checkout (an sdist)")
    for commit in commits:
        res = subprocess.run(
            ["git", "-C", str(ROOT), "cat-file", "-e", f"{commit}^{{commit}}"], capture_output=True
        )
        assert res.returncode == 0, f"{cmd.doc}:{cmd.line}: {commit} is not a commit of this repository"


@pytest.mark.parametrize("cmd", _of(LAB), ids=str)
def test_lab_tool_lines_parse_their_flags(cmd, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(ROOT))  # lab/ is run from the repository's root
    cfg, code, out = run_in_process(["python", *cmd.words[1:]], monkeypatch, stop_at_parse=True)
    assert cfg is not None, f"{cmd}\nexit {code}:\n{out[-2000:]}"
