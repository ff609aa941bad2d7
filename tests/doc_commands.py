"""The shell commands of the README, the user guides and the model cards, as their programs would receive them:
the parser that `repo/test_docs_commands.py` checks every command with, and that tests running a guide's own
command line read it through."""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHIPPED_STUDENT = ROOT / "models" / "student_cpu"  # what a `<checkpoint>` placeholder stands for
SHELL_LANGS = {"bash", "sh", "shell", "console"}
OURS = re.compile(r"^(lerobot-[\w-]+|blindgrasp-[\w-]+)$")
PLACEHOLDER = re.compile(r"<([A-Za-z_][\w .-]*)>")
SEPARATORS = {"&&", "||", ";", "|", "&"}
PREFIXES = {"sudo", "nohup", "nice", "env", "time"}


def doc_files() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), ROOT / "robot_configs" / "README.md",
            *sorted(ROOT.glob("models/*/README.md"))]  # fmt: skip


@dataclass(frozen=True)
class DocCommand:
    doc: str
    line: int
    argv: tuple[str, ...]

    @property
    def program(self) -> str:
        return self.argv[0] if OURS.match(self.argv[0]) else f"python -m {self.argv[2]}"

    def __str__(self) -> str:
        return f"{self.doc}:{self.line}: {shlex.join(self.argv)}"


def shell_blocks(text: str):
    """(first line number, lines) of each shell-language fenced block."""
    lines, block, start = text.splitlines(), None, 0
    for i, line in enumerate(lines, 1):
        fence = re.match(r"^\s*```+\s*([\w-]*)", line)
        if fence and block is None:
            block, start = ([] if fence.group(1).lower() in SHELL_LANGS else False), i + 1
        elif fence:
            if block:
                yield start, block
            block = None
        elif block is not False and block is not None:
            block.append(line)


def concrete(line: str) -> str:
    line = re.sub(r"<checkpoint>(/pretrained_model)?", str(SHIPPED_STUDENT), line)
    return PLACEHOLDER.sub(lambda m: re.sub(r"\W+", "_", m.group(1)), line)


def commands_of(doc: Path) -> list[DocCommand]:
    out = []
    for start, block in shell_blocks(doc.read_text()):
        logical, first = "", start
        for k, raw in enumerate(block):
            text = raw[2:] if raw.startswith("$ ") else raw
            if not logical:
                first = start + k
            logical += text.rstrip()[:-1] + " " if text.rstrip().endswith("\\") else text
            if text.rstrip().endswith("\\"):
                continue
            lexer = shlex.shlex(concrete(logical), posix=True, punctuation_chars=";&|")
            lexer.whitespace_split, lexer.commenters = True, "#"
            words, logical = list(lexer), ""
            for cmd in _split(words):
                if cmd and (OURS.match(cmd[0]) or _is_python_m(cmd)):
                    out.append(DocCommand(str(doc.relative_to(ROOT)), first, tuple(_python_m(cmd))))
    return out


def _split(words: list[str]):
    cmd: list[str] = []
    for w in words + [";"]:
        if w in SEPARATORS:
            while cmd and (cmd[0] in PREFIXES or re.match(r"^\w+=", cmd[0])):
                cmd.pop(0)  # `nice`, `sudo`, `VAR=value` in front of the command
            yield cmd
            cmd = []
        elif w not in ("...",):
            cmd.append(w)


def _is_python_m(cmd: list[str]) -> bool:
    return bool(re.match(r"^(\S*/)?python3?$", cmd[0])) and len(cmd) > 2 and cmd[1] == "-m" and \
        cmd[2].startswith(("lerobot_blindgrasp", "lerobot."))  # fmt: skip


def _python_m(cmd: list[str]) -> list[str]:
    return ["python", *cmd[1:]] if _is_python_m(cmd) else cmd


ALL = [c for d in doc_files() for c in commands_of(d)]
