"""Crash tests: SIGKILL at seeded random instants, and a full disk, for every long command and every file write.

The rule: a process can die at any instant and any write can fail; neither may cost more than the last bounded
interval of work, or any file that existed before. After each kill: every file that existed is intact or completely
replaced, re-running the same command finishes, and nothing finished is lost beyond the bound. A full disk is
simulated without root by RLIMIT_FSIZE in a subprocess (writes past the limit fail with EFBIG; Python ignores the
SIGXFSZ that would otherwise kill it).
"""

from __future__ import annotations

import hashlib
import json
import os
import random
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from lerobot_blindgrasp import durable, spec
from lerobot_blindgrasp.demos import dataset as demo_dataset
from lerobot_blindgrasp.demos import repair

SEED = 29  # every kill instant is drawn from this
ROOT = Path(__file__).resolve().parents[2]
ENV = {
    **os.environ,
    "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
    "HF_HUB_OFFLINE": "1",
    "OMP_NUM_THREADS": "1",
}


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _python(code: str, limit: int | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run `code` in a fresh interpreter; with `limit`, its writes past `limit` bytes fail with EFBIG from the line
    `LIMIT` on (set there, after the imports: torch and LeRobot write caches while they load)."""
    if limit:
        setrlimit = f"import resource; resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))\n"
        code = code.replace("LIMIT\n", setrlimit)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV, timeout=timeout)


def _kill_when(cmd: list[str], log: Path, ready, delay: float, timeout: float = 240) -> str:
    """Start `cmd` (output to `log`), wait until `ready(log text)` holds, wait `delay` s more, SIGKILL it."""
    with open(log, "w") as out:
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=ENV)
    deadline = time.monotonic() + timeout
    while not ready(log.read_text()):
        assert proc.poll() is None, f"{cmd[2]} ended before the kill point:\n{log.read_text()[-3000:]}"
        assert time.monotonic() < deadline, f"{cmd[2]} never reached the kill point"
        time.sleep(0.05)
    time.sleep(delay)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    return log.read_text()


def _run(cmd: list[str], timeout: float = 900) -> subprocess.CompletedProcess:
    proc = subprocess.run(cmd, capture_output=True, text=True, env=ENV, timeout=timeout)
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-4000:]
    return proc


# --- the atomic-write helper -----------------------------------------------------------------------------------
def test_atomic_writes_replace_whole_files_and_leave_no_temp(tmp_path):
    p = tmp_path / "sub" / "a.json"
    durable.atomic_write_json(p, {"x": 1}, indent=2)
    durable.atomic_write_text(p, '{"x": 2}')
    assert json.loads(p.read_text()) == {"x": 2}
    durable.atomic_write_bytes(tmp_path / "b.bin", b"\0" * 10)
    with durable.atomic_open(tmp_path / "c.txt") as f:
        f.write("hello")
    assert (tmp_path / "c.txt").read_text() == "hello"
    with pytest.raises(ZeroDivisionError), durable.atomic_path(p) as tmp:  # a failing writer: nothing replaced
        tmp.write_text("half")
        raise ZeroDivisionError("the writer failed")
    assert json.loads(p.read_text()) == {"x": 2}
    assert not [f for f in tmp_path.rglob("*") if durable.TEMP_MARK in f.name]


def test_sigkill_during_atomic_writes_leaves_the_old_or_the_new_file(tmp_path):
    """A writer that keeps replacing a 256 kB file with alternating contents, killed at 6 seeded instants: the file
    is always one complete version, never a mix or a truncation."""
    target = tmp_path / "big.bin"
    versions = {bytes([i]) * (256 << 10) for i in (1, 2)}
    # durable.py by its path: it needs only the standard library, and a start without torch keeps each cycle short.
    code = (
        "import importlib.util as u\n"
        f"s = u.spec_from_file_location('durable', {str(ROOT / 'lerobot_blindgrasp' / 'durable.py')!r})\n"
        "durable = u.module_from_spec(s); s.loader.exec_module(durable)\n"
        f"p = {str(target)!r}; i = 0\n"
        "while True:\n"
        "    durable.atomic_write_bytes(p, bytes([1 + i % 2]) * (256 << 10)); i += 1\n"
        "    print(i, flush=True)\n"
    )
    rng = random.Random(SEED)
    for k in range(6):
        log = tmp_path / f"w{k}.log"
        _kill_when([sys.executable, "-c", code], log, lambda t: t.count("\n") >= 2, rng.uniform(0.0, 0.05))
        assert target.read_bytes() in versions
    # The killed writers' temp files are the only leftovers, and they are recognisable.
    stale = durable.remove_stale_temps(tmp_path)
    assert all(durable.TEMP_MARK in p.name for p in stale)


def test_a_full_disk_keeps_the_old_file_and_says_so(tmp_path):
    """EFBIG (RLIMIT_FSIZE) during a write: old file byte-identical, an error naming the file and the file-size
    limit, for plain writes and for a third-party writer (torch.save) that reports a generic RuntimeError."""
    p, ckpt = tmp_path / "cfg.json", tmp_path / "model_1.pt"
    durable.atomic_write_json(p, {"old": True})
    torch.save({"w": torch.zeros(4)}, ckpt)
    before = _sha(p), _sha(ckpt)
    code = (
        "import torch\nfrom lerobot_blindgrasp import durable\nLIMIT\n"
        "try:\n"
        f"    durable.atomic_write_text({str(p)!r}, 'x' * 200000)\n"
        "except durable.WriteError as e:\n"
        "    print('TEXT', e.errno, e)\n"
        "try:\n"
        f"    with durable.atomic_path({str(ckpt)!r}) as tmp:\n"
        "        torch.save({'w': torch.zeros(100000)}, tmp)\n"
        "except durable.WriteError as e:\n"
        "    print('TORCH', e.errno, e)\n"
    )
    out = _python(code, limit=100_000)
    assert out.returncode == 0, out.stderr[-3000:]
    lines = dict(line.split(" ", 1) for line in out.stdout.splitlines())
    assert str(p) in lines["TEXT"] and "file-size limit" in lines["TEXT"] and "EFBIG" in lines["TEXT"]
    assert str(ckpt) in lines["TORCH"] and "file-size limit" in lines["TORCH"]
    assert (_sha(p), _sha(ckpt)) == before
    assert not [f for f in tmp_path.iterdir() if durable.TEMP_MARK in f.name]


def test_calibrations_on_a_full_disk_keep_the_old_file_and_blame_the_disk_not_the_bus(tmp_path):
    """The gripper and glove calibration saves (LeRobot's base class writes in place) under a file-size limit
    smaller than the new file: the old calibration survives, and the gripper's safety latch passes on a disk
    error instead of calling it a Dynamixel bus failure."""
    robot_file, glove_file = tmp_path / "robot" / "g.json", tmp_path / "glove" / "h.json"
    for f in (robot_file, glove_file):
        f.parent.mkdir()
        f.write_text('{"old": "calibration"}')
    code = f"""
from pathlib import Path
from lerobot.motors import MotorCalibration
from lerobot_blindgrasp import durable
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper, BlindgraspGripperConfig
from lerobot_blindgrasp.teleoperators.manus_glove import ManusGlove, ManusGloveConfig
from lerobot_blindgrasp.teleoperators.manus_glove.manus_glove import GloveCalibration
LIMIT
robot = BlindgraspGripper(BlindgraspGripperConfig(id="g", calibration_dir=Path({str(robot_file.parent)!r})))
robot.calibration = {{j: MotorCalibration(id=i + 1, drive_mode=0, homing_offset=0, range_min=0, range_max=4095)
                     for i, j in enumerate(robot.joints)}}
try:
    with robot.latch.guard("calibrating"):
        robot._save_calibration()
except Exception as e:
    print("ROBOT", type(e).__name__, e)
glove = ManusGlove(ManusGloveConfig(id="h", calibration_dir=Path({str(glove_file.parent)!r})))
glove.calibration = GloveCalibration(open={{"a": 0.0}}, fist={{"a": 90.0}})
try:
    glove._save_calibration()
except Exception as e:
    print("GLOVE", type(e).__name__, e)
"""
    out = _python(code, limit=len(robot_file.read_text()) + 20)
    assert out.returncode == 0, out.stderr[-3000:]
    got = dict(line.split(" ", 1) for line in out.stdout.splitlines())
    assert got["ROBOT"].startswith("WriteError") and "file-size limit" in got["ROBOT"]
    assert str(robot_file) in got["ROBOT"]
    assert "bus failure" not in got["ROBOT"]
    assert got["GLOVE"].startswith("WriteError") and str(glove_file) in got["GLOVE"]
    assert robot_file.read_text() == glove_file.read_text() == '{"old": "calibration"}'


# --- teacher training --------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_teacher_killed_at_random_instants_resumes_from_the_newest_readable_checkpoint(tmp_path):
    out = tmp_path / "run"
    cmd = [
        sys.executable,
        "-m",
        "lerobot_blindgrasp.teacher.train",
        "--preset=quick",
        f"--output_dir={out}",
        "--iterations=3",
        "--num_envs=18",
        "--threads=1",
        "--export=false",
    ]
    rng = random.Random(SEED)
    _kill_when(cmd, tmp_path / "t0.log", lambda _: (out / "model_0.pt").exists(), rng.uniform(0.0, 1.5))
    kept = {p.name: _sha(p) for p in out.glob("model_*.pt")}
    assert kept and not (out / "train_summary.json").exists()
    # A checkpoint cut short, as rsl-rl's in-place save leaves one on a kill: the resume must step over it.
    newest = max(out.glob("model_*.pt"), key=lambda p: int(p.stem.split("_")[1]))
    cut = out / f"model_{int(newest.stem.split('_')[1]) + 1}.pt"
    cut.write_bytes(newest.read_bytes()[: newest.stat().st_size // 2])
    done = _run(cmd)
    assert f"{cut} cannot be read" in done.stderr and (out / f"{cut.name}.corrupt").exists()
    assert f"resuming from {newest}" in done.stderr
    summary = json.loads((out / "train_summary.json").read_text())
    assert summary["iterations"] == 3 and not summary["interrupted"]
    for name, sha in kept.items():  # every checkpoint that existed is intact
        assert _sha(out / name) == sha
    assert torch.load(out / "model_2.pt", weights_only=False)["iter"] == 2


# --- demo collection ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def teacher(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("teacher") / "quick"
    _run(
        [
            sys.executable,
            "-m",
            "lerobot_blindgrasp.teacher.train",
            "--preset=quick",
            f"--output_dir={out}",
            "--iterations=1",
            "--num_envs=18",
            "--threads=1",
            "--export=false",
        ]
    )
    return out


DURABLE = re.compile(r"checkpoint: (\d+) episodes durable")


@pytest.mark.slow
def test_demo_collection_killed_at_random_instants_loses_at_most_one_batch_and_resumes(teacher, tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    root = tmp_path / "demos"
    n_envs, per_object = 3, 5
    cmd = [
        sys.executable,
        "-m",
        "lerobot_blindgrasp.demos.collect_cli",
        f"--teacher={teacher}",
        f"--output_dir={root}",
        "--repo_id=test/crash",
        f"--episodes_per_object={per_object}",
        f"--num_envs={n_envs}",
        "--objects=cylinder_a_medium,cuboid_a_medium",
        "--curation.enabled=false",
        "--progress=false",
        "--threads=1",
        f"--seed={spec.DEMO_SEED + 29}",
    ]
    rng = random.Random(SEED + 1)
    durable_before, logs, unfinished = 0, [], []
    for k in range(2):

        def ready(t, n=durable_before):
            return len(DURABLE.findall(t)) > 0 and int(DURABLE.findall(t)[-1]) > n

        again = cmd + (["--resume=true"] if k else [])
        log = _kill_when(again, tmp_path / f"d{k}.log", ready, rng.uniform(0, 0.5))
        logs.append(log)
        durable_now = int(DURABLE.findall(log)[-1])
        found = repair.repair(root, dry_run=True)
        # Nothing finished is lost beyond the bound: every checkpointed episode is kept.
        assert found.kept_episodes >= durable_now >= durable_before
        touched = {root / line.split(" (")[0] for line in found.rebuilt.set_aside} if found.rebuilt else set()
        intact = {p: _sha(p) for p in root.glob("data/*/*.parquet") if p not in touched}
        unfinished.append(found.changed)
        durable_before = found.kept_episodes
    done = _run(cmd + ["--resume=true"])
    logs.append(done.stdout + done.stderr)
    for k in range(2):  # the resume says what it repaired whenever the kill left unfinished files
        assert ("repaired it" in logs[k + 1]) == unfinished[k]
    for p, sha in intact.items():  # finalized files that existed are intact
        assert _sha(p) == sha, p
    ds = LeRobotDataset("test/crash", root=root)
    assert ds.meta.total_episodes == 2 * per_object
    assert not demo_dataset.check_schema(ds.meta.features, ds.meta.fps, ds.meta.robot_type)
    assert len(ds) == ds.meta.total_frames and int(ds[len(ds) - 1]["index"]) == len(ds) - 1
    runs = json.loads((root / "collection.json").read_text())["runs"]
    assert runs[0]["stop_reason"].startswith("killed") and runs[-1]["stop_reason"] == "done" and len(runs) == 3
    assert repair.repair(root).changed is False  # consistent: the repair is a no-op


def test_repair_keeps_every_saved_episode_of_a_crashed_recording_idempotently(tmp_path):
    """A LeRobot dataset written and finalized, then crashed while writing more (what lerobot-record leaves): the
    repair keeps the finalized episodes and the two saved after them (their rows rebuilt from the footerless data
    file, which is set aside), and a second run changes nothing."""
    import numpy as np
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    root = tmp_path / "rec"
    code = f"""
import os, numpy as np
from lerobot_blindgrasp import spec
from lerobot_blindgrasp.demos import dataset as d
ds = d.create({str(root)!r}, "test/rec")
def ep(i):
    n = 20 + i
    for t in range(n):
        ds.add_frame({{spec.STATE_KEY: np.full(12, i, np.float32), spec.ACTION_KEY: np.full(9, t, np.float32),
                      "episode.outcome": np.zeros(6, np.float32), "episode.randomization": np.zeros(7, np.float32),
                      "episode.seed": np.array([i, 0]), "task": "grasp"}})
    ds.save_episode()
for i in range(3):
    ep(i)
ds.finalize()
ds = d.resume({str(root)!r}, "test/rec")
for i in range(3, 5):
    ep(i)
os.kill(os.getpid(), 9)   # no finalize: footerless files, metadata claiming 5 episodes
"""
    _python(code)
    assert json.loads((root / "meta/info.json").read_text())["total_episodes"] == 5
    with pytest.raises(Exception):  # noqa: B017 (whatever pyarrow raises on a footerless file)
        LeRobotDataset("test/rec", root=root)
    report = repair.repair(root)
    assert (
        report.kept_episodes == 5 and report.lost_episodes == [] and report.kept_frames == 20 + 21 + 22 + 23 + 24
    )
    assert report.rebuilt is not None and any("file-001" in f for f in report.rebuilt.set_aside)
    ds = LeRobotDataset("test/rec", root=root)
    assert ds.meta.total_episodes == 5 and len(ds) == 110
    stats = json.loads((root / "meta/stats.json").read_text())
    assert stats[spec.STATE_KEY]["max"][0] == 4.0 and stats[spec.STATE_KEY]["count"] == [110]
    np.testing.assert_array_equal(ds[109][spec.STATE_KEY].numpy(), np.full(12, 4.0))
    before = {p: _sha(p) for p in root.rglob("*") if p.is_file()}
    assert not repair.repair(root).changed
    assert {p: _sha(p) for p in root.rglob("*") if p.is_file()} == before
    # Recording goes on after the last saved episode.
    ds = demo_dataset.resume(root, "test/rec")
    assert ds.meta.total_episodes == 5
    ds.finalize()


# --- the pipeline ------------------------------------------------------------------------------------------------
def _processes_mentioning(text: str) -> list[int]:
    pids = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if text in (d / "cmdline").read_bytes().decode(errors="replace"):
                    pids.append(int(d.name))
            except OSError:
                pass
    return pids


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_pipeline_killed_in_a_stage_reruns_only_unfinished_stages(tmp_path):
    """SIGKILL the smoke pipeline at a seeded instant inside the teacher stage, then again inside the next stage:
    the stage's own process dies with it, the killed stage is never marked completed, and the re-run skips exactly
    the completed stages and resumes the killed one. (The whole smoke pipeline to its end: test_pipeline.py.)"""
    out = tmp_path / "pipe"
    cmd = [sys.executable, "-m", "lerobot_blindgrasp.pipeline.run", "--preset=smoke", f"--output_dir={out}"]
    rng = random.Random(SEED + 2)
    _kill_when(cmd, tmp_path / "p0.log", lambda t: "[pipeline] teacher:" in t, rng.uniform(1.0, 6.0))
    time.sleep(0.5)
    assert not _processes_mentioning(str(out / "teacher")), "the teacher stage outlived the pipeline"
    record = json.loads((out / "pipeline.json").read_text()) if (out / "pipeline.json").exists() else {}
    assert "teacher" not in record.get("completed", [])
    log = _kill_when(cmd, tmp_path / "p1.log", lambda t: "[pipeline] teacher_eval:" in t, rng.uniform(0.5, 3.0))
    assert "[pipeline] teacher done" in log
    assert json.loads((out / "pipeline.json").read_text())["completed"] == ["teacher"]
    teacher_files = {p: _sha(p) for p in (out / "teacher").glob("model_*.pt")}
    log = _kill_when(cmd, tmp_path / "p2.log", lambda t: "[pipeline] demos:" in t, 0.0)
    assert "[pipeline] teacher: skipped (trained)" in log and "[pipeline] teacher_eval done" in log
    assert {p: _sha(p) for p in (out / "teacher").glob("model_*.pt")} == teacher_files
