"""The twin's own trial log: a trial the host aborted (it closed its connection without ending the trial, as on
SIGTERM) is never recorded as a success, even when the physics completes the lift after the host let go.

Driven through the real socket protocol, with the host's side (`SocketOperator`); the physics is not stepped: its
verdict is delivered the way its thread delivers one (`on_verdict`), after or before the host left."""

from __future__ import annotations

import json
import time

import pytest

from lerobot_blindgrasp.envs.operator import SocketOperator
from lerobot_blindgrasp.twin.command import TwinConfig
from lerobot_blindgrasp.twin.physics import TrialVerdict
from lerobot_blindgrasp.twin.runner import Twin


def _records(log, n: int, timeout_s: float = 30.0) -> list[dict]:
    deadline = time.monotonic() + timeout_s
    while not (log.exists() and len(log.read_text().splitlines()) >= n):
        assert time.monotonic() < deadline, "the twin never wrote its trial record"
        time.sleep(0.01)
    return [json.loads(line) for line in log.read_text().splitlines()]


@pytest.fixture
def twin(tmp_path):
    twin = Twin(TwinConfig(socket=str(tmp_path / "twin.sock"), trial_log=str(tmp_path / "trials.jsonl")))
    twin.server.empty_claw_after_s = 0.0  # the operator empties the claw at once: the record comes now
    twin.server.start()
    yield twin
    twin.server.stop()


def _start_trial(twin, seed: int) -> tuple[SocketOperator, int]:
    host = SocketOperator(twin.cfg.socket)
    host.announce_trial("sphere_medium", seed)
    assert host.wait_for({"enter"}, timeout_s=30) == "enter"
    return host, twin.physics.trial


@pytest.mark.parametrize("verdict_before_leaving", [False, True])
def test_a_trial_the_host_left_is_an_aborted_failure(twin, tmp_path, verdict_before_leaving):
    """The host leaves (SIGTERM: it unwinds, turns the torque off, its socket closes without an "end"), after the
    physics had judged the lift a success or before it could: either way the record is an aborted failure, and a
    verdict the physics reaches afterwards changes nothing."""
    host, trial = _start_trial(twin, 0)
    if verdict_before_leaving:
        twin.server._on_verdict(TrialVerdict(trial, True, "lifted"))
        assert host.wait_for({"s", "f"}, timeout_s=30) == "s"
    host.stop()
    (record,) = _records(tmp_path / "trials.jsonl", 1)
    assert not twin.physics.judging  # stopped as soon as the host was gone
    twin.server._on_verdict(
        TrialVerdict(trial, True, "lifted")
    )  # the physics thread's late verdict: no new record
    assert len(_records(tmp_path / "trials.jsonl", 1)) == 1
    assert record["trial"] == trial and record["aborted"] is True and record["success"] is False
    assert ("physics verdict: success" in record["reason"]) == verdict_before_leaving


def test_a_trial_the_host_ended_keeps_the_physics_verdict(twin, tmp_path):
    host, trial = _start_trial(twin, 1)
    twin.server._on_verdict(TrialVerdict(trial, True, "lifted"))
    assert host.wait_for({"s", "f"}, timeout_s=30) == "s"
    host.clear()  # the host's trial is over: "end"
    (record,) = _records(tmp_path / "trials.jsonl", 1)
    assert record["trial"] == trial and record["success"] is True and record["aborted"] is False
    host.stop()
