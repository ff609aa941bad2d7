"""`python -m lab.run_records`: a run's folder packed into one record gives the same bytes back, and every record the
docs cite unpacks into a folder the tools that made it still read."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from lab import run_records as records
from lab.twin_campaign import report

ROOT = Path(__file__).resolve().parents[2]
RECORDS = sorted((ROOT / "docs" / "results").rglob("*.json"))
PACKED = [p for p in RECORDS if set(json.loads(p.read_text())) == {"files"}]


def test_a_folder_round_trips_byte_for_byte(tmp_path):
    run = tmp_path / "run"
    (run / "calibration").mkdir(parents=True)
    (run / "calibration" / "twin.json").write_text(json.dumps({"a": [1, 2]}, indent=2))  # no final newline
    (run / "eval_info.json").write_text(json.dumps({"b": 0.5}, indent=1) + "\n")
    (run / "compact.json").write_text(json.dumps({"c": None}))
    (run / "trials.jsonl").write_text('{"seed": 1, "success": true}\n{"seed": 2, "success": false}\n')
    (run / "spaced.jsonl").write_text('{"seed":  1}\n')  # not json.dumps's spacing: kept as text
    (run / "twin.log").write_text("twin 1.0\nno final newline")
    record_file = tmp_path / "run.json"
    subprocess.run(
        [sys.executable, "-m", "lab.run_records", f"--pack={run}", f"--record={record_file}"], check=True, cwd=ROOT
    )
    kinds = {
        e["path"]: set(e) - {"path", "indent", "newline"} for e in json.loads(record_file.read_text())["files"]
    }
    assert kinds["trials.jsonl"] == {"jsonl"} and kinds["spaced.jsonl"] == {"text"}
    assert kinds["calibration/twin.json"] == {"json"} and kinds["twin.log"] == {"text"}
    back = tmp_path / "back"
    subprocess.run(
        [sys.executable, "-m", "lab.run_records", f"--unpack={record_file}", f"--to={back}"], check=True, cwd=ROOT
    )
    files = sorted(p.relative_to(run) for p in run.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(back) for p in back.rglob("*") if p.is_file())
    assert all((run / f).read_bytes() == (back / f).read_bytes() for f in files)


@pytest.mark.parametrize("record_file", PACKED, ids=lambda p: p.relative_to(ROOT / "docs").as_posix())
def test_every_packed_record_repacks_to_itself(record_file, tmp_path):
    record = json.loads(record_file.read_text())
    records.unpack(record, tmp_path)
    assert records.pack(tmp_path) == record


def test_the_twin_report_reads_an_unpacked_record(tmp_path):
    """The recorded report comes back whole from the recorded logs, by the report's own code: the twin's
    per-object table, its pairing with the sim env's recorded eval, the forces, the loop's timing and the load."""
    run, sim = tmp_path / "run", tmp_path / "sim"
    records.unpack(json.loads((ROOT / "docs/results/twin/measure.json").read_text()), run)
    sim.mkdir()
    (sim / "eval_info.json").write_bytes((run / "sim_eval_info.json").read_bytes())
    recorded = (run / "report.md").read_text()
    assert "Paired with the sim env" in recorded
    assert report.render(run, sim) == recorded
