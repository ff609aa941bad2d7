"""`blindgrasp-glove-bridge`: the MANUS ROS 2 publisher's glove topics -> the glove receiver's UDP datagrams.

    ros2 run manus_ros2 manus_data_publisher          # MANUS's node: topics manus_glove_0, manus_glove_1, ...
    blindgrasp-glove-bridge --side=right              # this bridge, on the same machine as lerobot-record
    blindgrasp-glove-bridge --side=right --host=192.168.1.20   # ... or sending to the robot PC at that address

The MANUS publisher (`manus_data_publisher`) publishes one `manus_ros2_msgs/msg/ManusGlove` per glove and frame:
`glove_id`, `side` ("Left" | "Right"), `raw_nodes`, `ergonomics` (a list of `ManusErgonomics`: `type`, the
ergonomics name as a side-less string, and `value`, degrees), `raw_sensor...`. The bridge subscribes to the
configured topics, keeps the messages of its hand, re-keys their ergonomics by channel (`names.py`) and sends one
datagram each (`protocol.py`), numbered and stamped on this machine's monotonic clock. `ManusGlove` carries no
time stamp, so the stamp is when the bridge got the message; the subscription keeps only the newest message
(depth 1), so a bridge that falls behind drops old ones instead of stamping them late as new.

rclpy and `manus_ros2_msgs` are imported only by `run()`: the package and its tests work without ROS 2. Without
ROS 2, a few lines on the MANUS SDK send the same datagrams: docs/glove.md.
"""

from __future__ import annotations

import logging
import sys
import time
from dataclasses import dataclass, field

from lerobot_blindgrasp.cli import parse_config

from . import names
from .protocol import GloveSender
from .retarget import REQUIRED_KEYS

logger = logging.getLogger(__name__)


class BridgeError(RuntimeError):
    """The bridge cannot run (no ROS 2, no MANUS messages, port taken); the message says what to do."""


@dataclass
class GloveBridgeConfig:
    # The receiver: the address of the machine running lerobot-record.
    host: str = "127.0.0.1"
    # The receiver's port (its --teleop.port).
    port: int = 50120
    # The hand to forward ("left" | "right"), as the teleoperator's --teleop.side.
    side: str = "right"
    # The MANUS publisher's topics (one per glove, numbered in the order MANUS Core reports the gloves).
    topics: list[str] = field(default_factory=lambda: ["manus_glove_0", "manus_glove_1"])
    # This bridge's UDP source port, fixed so that a restarted bridge keeps its address, the one the receiver is
    # bound to (--teleop.sender=<this machine>:<source_port>). 0: any free port.
    source_port: int = 50121
    # How often to log what was forwarded (s); 0: never.
    status_every_s: float = 10.0

    def __post_init__(self):
        if self.side not in names.SIDES:
            raise ValueError(f"side must be 'left' or 'right', not {self.side!r}")
        if not 0 < self.port < 65536 or not 0 <= self.source_port < 65536:
            raise ValueError("need 0 < port < 65536 and 0 <= source_port < 65536")
        if not self.topics:
            raise ValueError("topics is empty: name at least one of the publisher's topics (manus_glove_0)")


def _field(msg, name: str):
    """A message field, from a ROS message object or a dict of its fields (rosidl_runtime_py's conversion)."""
    if isinstance(msg, dict):
        if name not in msg:
            raise ValueError(f"message has no field {name!r}")
        return msg[name]
    if not hasattr(msg, name):
        raise ValueError(f"message has no field {name!r}")
    return getattr(msg, name)


def ergonomics_from_message(msg) -> tuple[str, dict[str, float], list[str]]:
    """One `manus_ros2_msgs/msg/ManusGlove` -> (side, ergonomics by channel, type strings not understood).

    Pure: no ROS needed. Raises ValueError on a message of another shape or an "Invalid" side."""
    side = str(_field(msg, "side")).lower()
    if side not in names.SIDES:
        raise ValueError(f"glove side {_field(msg, 'side')!r} is not Left or Right")
    values: dict[str, float] = {}
    unknown: list[str] = []
    for item in _field(msg, "ergonomics"):
        kind, value = str(_field(item, "type")), float(_field(item, "value"))
        if kind in names.ALIASES:
            values[kind] = value
        else:
            unknown.append(kind)  # e.g. "Invalid", from publishers that cannot name a channel
    by_channel, problems = names.canonical(values, side)
    if problems:
        raise ValueError("; ".join(problems))
    return side, {k: float(v) for k, v in by_channel.items()}, unknown


class GloveBridge:
    """The bridge's work per message, apart from ROS: filter by hand, re-key, send."""

    def __init__(self, cfg: GloveBridgeConfig, sender: GloveSender | None = None):
        self.cfg = cfg
        self.sender = sender or GloveSender(cfg.host, cfg.port, cfg.side, source_port=cfg.source_port)
        self.forwarded = self.other_hand = self.bad = self.send_errors = 0
        self._warned: set[frozenset[str]] = set()

    def forward(self, msg) -> bool:
        """Send `msg` if it is this bridge's hand; False if it was skipped. Never raises on a bad message."""
        try:
            side, ergonomics, unknown = ergonomics_from_message(msg)
        except (ValueError, TypeError) as e:
            self.bad += 1
            logger.warning("Skipping a glove message: %s", e)
            return False
        if side != self.cfg.side:
            self.other_hand += 1
            return False
        missing = frozenset(REQUIRED_KEYS - ergonomics.keys())
        if missing and missing not in self._warned:
            self._warned.add(missing)
            logger.warning("The %s glove's messages lack %s (types not understood: %s): the receiver refuses them "
                           "unless that finger's --teleop.spread_gain is 0. See docs/glove.md, 'Names'.", side,
                           sorted(missing), sorted(set(unknown)))  # fmt: skip
        try:
            self.sender.send(ergonomics)
        except OSError as e:  # no route to the receiver yet (link down, wrong --host): keep going, say it once
            self.send_errors += 1
            if self.send_errors == 1:
                logger.warning("Cannot send to %s:%d: %s (check --host and the network)", *self.sender.addr, e)
            return False
        self.forwarded += 1
        return True

    def status(self) -> str:
        return (
            f"forwarded {self.forwarded} {self.cfg.side}-hand messages to {self.cfg.host}:{self.cfg.port} "
            f"(session {self.sender.session}); skipped {self.other_hand} of the other hand, {self.bad} bad, "
            f"{self.send_errors} not sent"
        )


def _import_ros():
    try:
        import rclpy
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    except ImportError as e:
        raise BridgeError(
            f"rclpy is not importable ({e}): this command runs inside a ROS 2 environment (source "
            "/opt/ros/<distro>/setup.bash first). Without ROS 2, send the datagrams from the MANUS SDK: docs/glove.md."
        ) from e
    try:
        from manus_ros2_msgs.msg import ManusGlove
    except ImportError as e:
        raise BridgeError(
            f"manus_ros2_msgs is not importable ({e}): build MANUS's ROS 2 package (colcon build) and source its "
            "workspace (source install/setup.bash) in this shell."
        ) from e
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
    return rclpy, ManusGlove, qos


def run(cfg: GloveBridgeConfig) -> None:
    rclpy, glove_msg, qos = _import_ros()
    try:
        bridge = GloveBridge(cfg)
    except ConnectionError as e:
        raise BridgeError(str(e)) from e
    rclpy.init()
    node = rclpy.create_node("blindgrasp_glove_bridge")
    for topic in cfg.topics:
        node.create_subscription(glove_msg, topic, bridge.forward, qos)
    if cfg.status_every_s > 0:
        node.create_timer(cfg.status_every_s, lambda: logger.info("%s", bridge.status()))
    logger.info("Bridging %s (%s hand) to udp://%s:%d from source port %d, session %s.", cfg.topics, cfg.side,
                cfg.host, cfg.port, bridge.sender.source[1], bridge.sender.session)  # fmt: skip
    t0 = time.monotonic()
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        logger.info("%s, in %.0f s.", bridge.status(), time.monotonic() - t0)
        node.destroy_node()
        if rclpy.ok():  # Ctrl-C may have shut the context down already (Humble has no module-level try_shutdown)
            rclpy.shutdown()
        bridge.sender.close()


def main(argv: list[str] | None = None) -> None:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s")
    cfg = parse_config(GloveBridgeConfig, argv)
    try:
        run(cfg)
    except BridgeError as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(2) from None


if __name__ == "__main__":
    main()
