"""Configuration of the glove teleoperator (`--teleop.type=manus_glove`); the wire format is in `protocol.py`, the
bridge in `bridge.py`, the setup in docs/glove.md."""

from __future__ import annotations

from dataclasses import dataclass, field

from lerobot.teleoperators.config import TeleoperatorConfig

from .retarget import DEFAULT_CLOSED_POSE, DEFAULT_OPEN_POSE


@TeleoperatorConfig.register_subclass("manus_glove")
@dataclass
class ManusGloveConfig(TeleoperatorConfig):
    # The address this receiver listens on. 127.0.0.1: a bridge on this machine only. A bridge on another machine:
    # this machine's address on that network (or 0.0.0.0, all interfaces), best with `sender` pinned.
    host: str = "127.0.0.1"
    port: int = 50120
    side: str = "right"
    # The one bridge to accept, "host:port" (its source address). None: the first valid sender, until a reconnect.
    sender: str | None = None
    # Datagrams whose ergonomics repeat bit for bit this many times in a row count as stale (a bridge re-sending
    # cached data after the glove dropped). 0 (default): off, since a still hand may repeat filtered SDK values.
    frozen_frames: int = 0
    # First datagram must arrive within this time at connect.
    connect_timeout_s: float = 2.0
    # A datagram that was queued on the way longer than this (by the bridge's clock, beyond the fastest delivery
    # seen) is dropped: after a network pause the backlog is not replayed. At most hold_timeout_s.
    max_latency_s: float = 0.1
    # Newest datagram older than this: the target freezes at its last value, so the gripper stops moving.
    hold_timeout_s: float = 0.15
    # Older than this: get_action raises, which ends lerobot-record, whose cleanup turns the gripper torque off.
    disconnect_timeout_s: float = 1.0
    # Calibration: averaging window per pose, and the least flexion change (deg) open -> fist per channel.
    calibration_s: float = 1.0
    min_flex_range_deg: float = 15.0
    # Gripper targets (rad, spec.JOINT_NAMES order) for the operator's open hand and fist.
    open_pose: list[float] = field(default_factory=lambda: list(DEFAULT_OPEN_POSE))
    closed_pose: list[float] = field(default_factory=lambda: list(DEFAULT_CLOSED_POSE))
    # Abduction gain (rad of J*0 per rad of finger spread), per finger (ff, mf, th); the sign picks the direction.
    # 0: that finger's abduction stays at open_pose and its spread channel is not required (docs/glove.md).
    spread_gain: list[float] = field(default_factory=lambda: [1.0, 1.0, 1.0])

    def __post_init__(self):
        if self.side not in ("left", "right"):
            raise ValueError("side must be 'left' or 'right'")
        if len(self.open_pose) != 9 or len(self.closed_pose) != 9 or len(self.spread_gain) != 3:
            raise ValueError("open_pose and closed_pose need 9 values, spread_gain 3")
        if not 0 < self.hold_timeout_s < self.disconnect_timeout_s:
            raise ValueError("need 0 < hold_timeout_s < disconnect_timeout_s")
        if not 0 < self.max_latency_s <= self.hold_timeout_s:
            raise ValueError("need 0 < max_latency_s <= hold_timeout_s")
        if not 0 < self.port < 65536 or not self.connect_timeout_s > 0 or not self.calibration_s > 0:
            raise ValueError("need 0 < port < 65536, connect_timeout_s > 0 and calibration_s > 0")
        if self.frozen_frames < 0 or self.frozen_frames == 1:
            raise ValueError("frozen_frames must be 0 (off) or >= 2")
        self.sender_address()  # a malformed sender is refused here, not at the first datagram

    def sender_address(self) -> tuple[str, int] | None:
        if self.sender is None:
            return None
        host, sep, port = self.sender.rpartition(":")
        if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
            raise ValueError(f"sender must be 'host:port' (the bridge's source address), not {self.sender!r}")
        return host, int(port)
