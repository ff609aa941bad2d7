"""The twin assembled: servo bus and force board on pseudo-terminals, MuJoCo behind them stepped one substep at a time
against the monotonic clock, the operator socket beside them. A run whose `behind_s` is not ~0 did not keep real time.
"""

from __future__ import annotations

import logging
import sys
import threading
import time
from collections import deque

import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.emulators import mount
from lerobot_blindgrasp.emulators.dynamixel import DynamixelBusEmulator
from lerobot_blindgrasp.emulators.force_board import ForceSensorEmulator
from lerobot_blindgrasp.hardware.realtime import set_realtime_priority
from lerobot_blindgrasp.twin.operator_server import OperatorServer
from lerobot_blindgrasp.twin.physics import TwinPhysics
from lerobot_blindgrasp.twin.servo_link import SimShaft, read_commands

logger = logging.getLogger(__name__)


def percentiles_ms(values) -> dict[str, float]:
    v = np.asarray(list(values), dtype=np.float64) * 1e3
    if v.size == 0:
        return {"n": 0}
    p50, p99, top = (round(float(x), 3) for x in (*np.percentile(v, [50, 99]), v.max()))
    return {"n": int(v.size), "p50_ms": p50, "p99_ms": p99, "max_ms": top}


def make_realtime(threads: dict[str, threading.Thread], priority: int) -> str:
    """SCHED_FIFO at `priority` for each thread (the physics one step below the emulators, which must answer
    first); says what the emulators got. The kernel's RT throttling still leaves other processes 5 % of each core."""
    got = {
        name: set_realtime_priority(max(1, priority - 1) if name == "physics" else priority, t.native_id)
        for name, t in threads.items()
    }
    return got["bus"]


class Twin:
    def __init__(self, cfg):  # a twin.command.TwinConfig
        self.cfg = cfg
        self.physics = TwinPhysics(park_object=cfg.park_object)
        self.ids = list(spec.SERVO_IDS)
        self.bus = DynamixelBusEmulator(
            self.ids, baudrate=cfg.baudrate, initial_shaft=dict(zip(self.ids, mount.shaft_for_q(self.physics.q)))
        )
        self.servos = [self.bus.servos[i] for i in self.ids]
        for k, s in enumerate(self.servos):
            s.dynamics = SimShaft(self.physics, k)
        lc = cfg.load_cell
        self.force = ForceSensorEmulator(
            rate_hz=lc.rate_hz,
            scale_n_per_count=lc.true_scale(),
            offset_counts=lc.offset_counts,
            noise_counts=lc.noise_counts,
            seed=cfg.noise_seed,
            force_fn=lambda: self.physics.tip_force_n,
        )
        self.server = OperatorServer(cfg.socket, self, trial_log=cfg.trial_log)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="twin-physics", daemon=True)
        # Accounting: each control period's (10 substeps') compute time, and the time the physics spent behind.
        self.period_cost = deque(maxlen=20_000)
        self.behind_s = 0.0
        self.skips = 0
        self.max_lag_s = 0.0
        self.realtime = "off"
        self._t0_wall = self._t0_cpu = 0.0

    # --- lifecycle --------------------------------------------------------------------------------------------
    def start(self) -> Twin:
        # The physics thread must not hold the emulators' threads off for Python's default 5 ms GIL switch.
        sys.setswitchinterval(0.0005)
        self._t0_wall, self._t0_cpu = time.monotonic(), time.process_time()
        self._thread.start()
        self.bus.start()
        self.force.start()
        self.server.start()
        if self.cfg.realtime_priority > 0:
            threads = {"physics": self._thread, "bus": self.bus._thread, "force": self.force._thread}
            self.realtime = make_realtime(threads, self.cfg.realtime_priority)
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.server.stop()
        self.bus.stop()
        self.force.stop()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()

    def ports(self) -> dict[str, str]:
        return {
            "dynamixel_port": self.bus.port,
            "force_port": self.force.port,
            "operator_socket": self.cfg.socket,
            "scale_n_per_count": list(self.cfg.load_cell.scale_n_per_count),
        }

    # --- the real-time loop -----------------------------------------------------------------------------------
    def _run(self) -> None:
        dt = self.physics.options.timestep
        per_period = self.physics.options.substeps
        t_sim = time.monotonic()  # the wall-clock instant the physics has reached
        cost = 0.0
        while not self._stop.is_set():
            now = time.monotonic()
            if now < t_sim:
                time.sleep(t_sim - now)
                continue
            lag = now - t_sim
            self.max_lag_s = max(self.max_lag_s, lag)
            if lag > self.cfg.max_lag_s:  # starved: the world pauses rather than racing to catch up
                self.behind_s += lag
                self.skips += 1
                t_sim = now
            start = time.perf_counter()
            read_commands(self.servos, self.physics.command)
            self.physics.substep()
            cost += time.perf_counter() - start
            t_sim += dt
            if self.physics.substeps % per_period == 0:
                self.period_cost.append(cost)
                cost = 0.0

    def status(self) -> dict:
        wall = time.monotonic() - self._t0_wall
        return {
            "wall_s": round(wall, 1),
            "realtime": self.realtime,
            "sim_s": round(self.physics.substeps * self.physics.options.timestep, 1),
            "cpu_share_of_one_core": round((time.process_time() - self._t0_cpu) / max(wall, 1e-9), 3),
            "physics_cost_per_control_period": percentiles_ms(self.period_cost),
            "control_period_ms": spec.CONTROL_DT * 1e3,
            "behind_s": round(self.behind_s, 3),
            "skips": self.skips,
            "max_lag_ms": round(self.max_lag_s * 1e3, 1),
            "unstable_resets": self.physics.unstable_resets,
            "trials_placed": self.physics.trial,
            "force_frames_sent": self.force.sent,
        }
