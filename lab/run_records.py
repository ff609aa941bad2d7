"""One file per record: a run's folder of small files (JSON, JSON lines, logs) packed into one JSON, and back.

    python -m lab.run_records --pack=outputs/twin_run --record=docs/results/twin/measure.json
    python -m lab.run_records --unpack=docs/results/twin/measure.json --to=outputs/twin_run   # the files, byte for byte

A JSON file is kept as its value and a JSON-lines file as a list of values, so a reader (or `jq`) sees the data,
not an escaped string; anything else is kept as text. Each entry carries what it takes to write the file back with
the same bytes (the JSON indent and final newline), and `pack` refuses a file it could not give back exactly. So
the tools that read a run's folder (`python -m lab.twin_campaign.report --run=DIR`, `results.compare`) run on an
unpacked record unchanged.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from lerobot_blindgrasp import durable
from lerobot_blindgrasp.cli import parse_config

_INDENTS = (None, 1, 2)


def _entry(name: str, text: str) -> dict:
    """The record's entry for one file: its value where it reads back to the same bytes, else its text."""
    if name.endswith(".jsonl"):
        lines = text.splitlines()
        if text.endswith("\n") and all(line and json.dumps(json.loads(line)) == line for line in lines):
            return {"path": name, "jsonl": [json.loads(line) for line in lines]}
    elif name.endswith(".json"):
        value = json.loads(text)
        for indent in _INDENTS:
            body = json.dumps(value, indent=indent)
            if text in (body, body + "\n"):
                return {"path": name, "json": value, "indent": indent, "newline": text != body}
    return {"path": name, "text": text}


def file_text(entry: dict) -> str:
    """A record entry's file, as the bytes it had when packed (decoded)."""
    if "jsonl" in entry:
        return "".join(json.dumps(v) + "\n" for v in entry["jsonl"])
    if "json" in entry:
        return json.dumps(entry["json"], indent=entry["indent"]) + ("\n" if entry["newline"] else "")
    return entry["text"]


def pack(folder: Path) -> dict:
    """Every file under `folder` (sorted by path) as one record; a ValueError if one would not unpack exactly."""
    entries = []
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        entry = _entry(path.relative_to(folder).as_posix(), path.read_text())
        if file_text(entry) != path.read_text():
            raise ValueError(f"{path} would not unpack to the same bytes")
        entries.append(entry)
    return {"files": entries}


def unpack(record: dict, to: Path) -> list[Path]:
    """Write a record's files under `to` (each one atomically); their paths."""
    written = []
    for entry in record["files"]:
        path = to / entry["path"]
        path.parent.mkdir(parents=True, exist_ok=True)
        written.append(durable.atomic_write_text(path, file_text(entry)))
    return written


@dataclass
class RecordsConfig:
    pack: Path | None = None  # a run's folder to pack (with --record)
    record: Path | None = None  # the record file --pack writes
    unpack: Path | None = None  # a record file to unpack (with --to)
    to: Path | None = None  # the folder --unpack fills


def main(argv: list[str] | None = None) -> None:
    """Pack a run's folder into one record file, or unpack a record into a folder."""
    cfg = parse_config(RecordsConfig, argv)
    if cfg.pack and cfg.record:
        durable.atomic_write_text(cfg.record, json.dumps(pack(cfg.pack), indent=1) + "\n")
        print(cfg.record)
    elif cfg.unpack and cfg.to:
        for path in unpack(json.loads(cfg.unpack.read_text()), cfg.to):
            print(path)
    else:
        raise SystemExit("give --pack=DIR --record=FILE, or --unpack=FILE --to=DIR")


if __name__ == "__main__":
    main()
