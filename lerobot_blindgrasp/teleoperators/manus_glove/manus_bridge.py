#!/usr/bin/env python3
"""The MANUS glove bridge: one hand's ergonomics -> `blindgrasp-glove/2` UDP datagrams for the manus_glove teleoperator.

One file needing only Python's standard library (3.10 or later) and, for `--source=ros2`, `rclpy`: copy it to the
machine that runs MANUS and start it there (docs/glove.md; `python3 manus_bridge.py --help`). It is also the
teleoperator's one source of the ergonomics names table (`CHANNELS`) and of the datagram (`encode`, `GloveSender`).
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import inspect
import json
import logging
import os
import re
import secrets
import signal
import socket
import sys
import threading
import time
from dataclasses import dataclass, field, fields

logger = logging.getLogger("manus_bridge")

# --- the names table: MANUS's ErgonomicsDataType (ManusSDKTypes.h) and the ROS 2 publisher's type strings -------
FINGERS = ("Thumb", "Index", "Middle", "Ring", "Pinky")
MOTIONS = ("MCPSpread", "MCPStretch", "PIPStretch", "DIPStretch")
SIDES = ("left", "right")
ENUM_PREFIX = "ErgonomicsDataType_"


@dataclass(frozen=True)
class Channel:
    name: str  # the receiver's key: the SDK enum name without prefix and side
    finger: str
    motion: str
    ros2: str  # the MANUS ROS 2 publisher's ManusErgonomics.type string

    def enum_name(self, side: str) -> str:
        return f"{ENUM_PREFIX}{side.capitalize()}Finger{self.name}"

    def enum_value(self, side: str) -> int:  # index into ErgonomicsData.data: the left hand's 20, then the right's
        return SIDES.index(side) * len(CHANNELS) + CHANNELS.index(self)


def _ros2_string(finger: str, motion: str) -> str:
    # The publisher drops "MCP" from the four finger spreads; the thumb keeps ThumbMCPSpread.
    return f"{finger}Spread" if motion == "MCPSpread" and finger != "Thumb" else f"{finger}{motion}"


CHANNELS = tuple(Channel(f"{f}{m}", f, m, _ros2_string(f, m)) for f in FINGERS for m in MOTIONS)
# The channels the gripper's retargeting reads (thumb, index, middle): the bridge warns when its hand lacks one.
USED_CHANNELS = frozenset(c.name for c in CHANNELS if c.finger in ("Thumb", "Index", "Middle"))


def _aliases() -> dict[str, tuple[str, str | None]]:
    """Every accepted key -> (channel, side it names or None)."""
    out: dict[str, tuple[str, str | None]] = {}
    for c in CHANNELS:
        out[c.name] = out[c.ros2] = (c.name, None)
        for side in SIDES:
            out[c.enum_name(side)] = out[c.enum_name(side).removeprefix(ENUM_PREFIX)] = (c.name, side)
    return out


ALIASES = _aliases()


def canonical(values: dict, side: str) -> tuple[dict[str, object], list[str]]:
    """Re-key `values` by channel name: (values by channel, problems). Unknown keys are ignored; a key naming the
    other hand, or two keys for one channel with different values, is a problem: the datagram cannot be trusted."""
    out: dict[str, object] = {}
    problems: list[str] = []
    for key, value in values.items():
        hit = ALIASES.get(key) if isinstance(key, str) else None
        if hit is None:
            continue
        name, named_side = hit
        if named_side is not None and named_side != side:
            problems.append(f"{key!r} is a {named_side}-hand channel in a {side}-hand datagram")
        elif name in out and out[name] != value:
            problems.append(f"two different values for {name}")
        else:
            out[name] = value
    return out, problems


# --- the datagram ----------------------------------------------------------------------------------------------
PROTO = "blindgrasp-glove/2"
SESSION_RE = re.compile(r"[0-9A-Za-z_-]{1,64}")


def encode(session: str, seq: int, sent: float, ergonomics: dict[str, float], side: str = "right") -> bytes:
    msg = {"proto": PROTO, "session": session, "seq": seq, "sent": sent, "side": side, "ergonomics": ergonomics}
    return json.dumps(msg).encode()


class GloveSender:
    """Numbers, stamps (this machine's monotonic clock) and sends datagrams for one hand. A fixed `source_port`
    keeps the bridge's address across restarts, so a receiver bound to it (`--teleop.sender`) accepts it again."""

    def __init__(self, host: str, port: int, side: str = "right", *, source_host: str = "",
                 source_port: int = 0, session: str | None = None):  # fmt: skip
        if side not in SIDES:
            raise ValueError(f"side must be 'left' or 'right', not {side!r}")
        self.addr, self.side = (host, port), side
        self.session, self.seq = session or secrets.token_hex(8), 0
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind((source_host, source_port))
        except OSError as e:
            self._sock.close()
            raise ConnectionError(f"Cannot send from udp port {source_port}: {e} (another bridge running?)") from e

    @property
    def source(self) -> tuple[str, int]:
        return self._sock.getsockname()

    def send(self, ergonomics: dict[str, float]) -> None:
        """The next datagram of this session, numbered and stamped now."""
        self.seq += 1
        self._sock.sendto(encode(self.session, self.seq, time.monotonic(), ergonomics, self.side), self.addr)

    def close(self) -> None:
        self._sock.close()


# --- the bridge's configuration and its work per hand pose -----------------------------------------------------
class BridgeError(RuntimeError):
    """The bridge cannot run (no ROS 2, no SDK library, an SDK call failed, port taken); the message says why."""


@dataclass
class BridgeConfig:
    # Where the hand comes from: "ros2" (MANUS's ROS 2 publisher) or "sdk" (the MANUS SDK's C library).
    source: str = "ros2"
    # The receiver: the address of the machine running lerobot-record.
    host: str = "127.0.0.1"
    # The receiver's port (its --teleop.port).
    port: int = 50120
    # The hand to forward ("left" | "right"), as the teleoperator's --teleop.side.
    side: str = "right"
    # ros2: the publisher's topics, one per glove (comma-separated).
    topics: list[str] = field(default_factory=lambda: ["manus_glove_0", "manus_glove_1"])
    # This bridge's UDP source port, fixed so a restarted bridge keeps its address (--teleop.sender); 0: any.
    source_port: int = 50121
    # How often to log what was forwarded (s); 0: never.
    status_every_s: float = 10.0
    # sdk: the library; empty: $MANUS_SDK_LIBRARY, else libManusSDK_Integrated.so (integrated) / libManusSDK.so.
    sdk_library: str = ""
    # sdk: "integrated" (the SDK drives the dongle itself) or "core" (connect to a MANUS Core on the network).
    sdk_mode: str = "integrated"
    # sdk, core mode: the host name or IP address of the MANUS Core to connect to; empty: the first one found.
    sdk_host: str = ""
    # sdk: the glove id to forward; 0: the glove whose side (from the SDK's landscape) is --side.
    glove_id: int = 0
    # sdk: how long to keep looking for a host to connect to (s).
    connect_timeout_s: float = 30.0

    def __post_init__(self):
        for name, allowed in (("source", ("ros2", "sdk")), ("side", SIDES), ("sdk_mode", ("integrated", "core"))):
            if getattr(self, name) not in allowed:
                raise ValueError(f"{name} must be {' or '.join(map(repr, allowed))}, not {getattr(self, name)!r}")
        if not 0 < self.port < 65536 or not 0 <= self.source_port < 65536:
            raise ValueError("need 0 < port < 65536 and 0 <= source_port < 65536")
        if not self.topics:
            raise ValueError("topics is empty: name at least one of the publisher's topics (manus_glove_0)")


def _field(msg, name: str):
    """A message field, from a ROS message object or a dict of its fields (rosidl_runtime_py's conversion)."""
    if not (name in msg if isinstance(msg, dict) else hasattr(msg, name)):
        raise ValueError(f"message has no field {name!r}")
    return msg[name] if isinstance(msg, dict) else getattr(msg, name)


def ergonomics_from_message(msg) -> tuple[str, dict[str, float], list[str]]:
    """One ROS 2 `ManusGlove` -> (side, ergonomics by channel, type strings not understood). Raises ValueError on
    a message of another shape or an "Invalid" side."""
    side = str(_field(msg, "side")).lower()
    if side not in SIDES:
        raise ValueError(f"glove side {_field(msg, 'side')!r} is not Left or Right")
    values: dict[str, float] = {}
    unknown: list[str] = []
    for item in _field(msg, "ergonomics"):
        kind, value = str(_field(item, "type")), float(_field(item, "value"))
        if kind in ALIASES:
            values[kind] = value
        else:
            unknown.append(kind)  # e.g. "Invalid", from publishers that cannot name a channel
    by_channel, problems = canonical(values, side)
    if problems:
        raise ValueError("; ".join(problems))
    return side, {k: float(v) for k, v in by_channel.items()}, unknown


class GloveBridge:
    """The work per hand pose, apart from where it comes from: filter by hand, re-key, send."""

    def __init__(self, cfg: BridgeConfig, sender: GloveSender | None = None):
        self.cfg = cfg
        self.sender = sender or GloveSender(cfg.host, cfg.port, cfg.side, source_port=cfg.source_port)
        self.forwarded = self.other_hand = self.bad = self.send_errors = 0
        self._warned: set[frozenset[str]] = set()

    def forward(self, msg) -> bool:
        """Send a ROS 2 `ManusGlove` if it is this bridge's hand; False if skipped. Never raises on a bad message."""
        try:
            side, ergonomics, unknown = ergonomics_from_message(msg)
        except (ValueError, TypeError) as e:
            self.bad += 1
            logger.warning("Skipping a glove message: %s", e)
            return False
        return self.deliver(side, ergonomics, unknown)

    def deliver(self, side: str, ergonomics: dict[str, float], unknown: list[str] = ()) -> bool:
        if side != self.cfg.side:
            self.other_hand += 1
            return False
        missing = frozenset(USED_CHANNELS - ergonomics.keys())
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
        return (f"forwarded {self.forwarded} {self.cfg.side}-hand poses to {self.cfg.host}:{self.cfg.port} (session "
                f"{self.sender.session}); skipped {self.other_hand} of the other hand, {self.bad} bad, "
                f"{self.send_errors} not sent")  # fmt: skip


# --- source 1: MANUS's ROS 2 publisher ----------------------------------------------------------------------------
def _import_ros():
    try:
        import rclpy
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    except ImportError as e:
        raise BridgeError(f"rclpy is not importable ({e}): --source=ros2 runs inside a ROS 2 environment (source "
                          "/opt/ros/<distro>/setup.bash first). Without ROS 2: --source=sdk (docs/glove.md).") from e  # fmt: skip
    for package in ("manus_ros2_msgs.msg", "manus_ros2.msg"):  # both spellings of MANUS's message package
        with contextlib.suppress(ImportError):
            glove_msg = __import__(package, fromlist=["ManusGlove"]).ManusGlove
            break
    else:
        raise BridgeError("neither manus_ros2_msgs.msg nor manus_ros2.msg has ManusGlove: build MANUS's ROS 2 "
                          "package (colcon build) and source its workspace (source install/setup.bash).")  # fmt: skip
    # Depth 1: a bridge that falls behind drops old messages instead of stamping them late as new.
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
    return rclpy, glove_msg, qos


def run_ros2(cfg: BridgeConfig, bridge: GloveBridge) -> None:
    rclpy, glove_msg, qos = _import_ros()
    from rclpy.executors import ExternalShutdownException  # ROS 2 Humble or later

    rclpy.init()
    node = rclpy.create_node("blindgrasp_glove_bridge")
    try:
        for topic in cfg.topics:
            node.create_subscription(glove_msg, topic, bridge.forward, qos)
        if cfg.status_every_s > 0:
            node.create_timer(cfg.status_every_s, lambda: logger.info("%s", bridge.status()))
        logger.info("Bridging %s (%s hand) to udp://%s:%d, session %s.", cfg.topics, cfg.side, cfg.host, cfg.port,
                    bridge.sender.session)  # fmt: skip
        rclpy.spin(node)
    except ExternalShutdownException:  # Ctrl-C or SIGTERM seen by rclpy's own handler: its context is shut down
        pass
    finally:
        node.destroy_node()
        if rclpy.ok():  # Ctrl-C may have shut the context down already (Humble has no module-level try_shutdown)
            rclpy.shutdown()


def run_bridge(cfg: BridgeConfig) -> None:
    """Forward until interrupted (KeyboardInterrupt, or the ROS 2 context shut down)."""
    if cfg.source == "ros2":
        _import_ros()  # before the socket: a machine without ROS 2 gets the message that says what to source
    try:
        bridge = GloveBridge(cfg)
    except ConnectionError as e:
        raise BridgeError(str(e)) from e
    t0 = time.monotonic()
    try:
        if cfg.source == "ros2":
            run_ros2(cfg, bridge)
        else:
            from_sdk(cfg, bridge)
    finally:
        logger.info("%s, in %.0f s.", bridge.status(), time.monotonic() - t0)
        bridge.sender.close()


# --- source 2: the MANUS SDK's C API (ManusSDK.h, ManusSDKTypes.h) through ctypes ---------------------------------
C = ctypes
RETURN_CODES = ("Success Error InvalidArgument ArgumentSizeMismatch UnsupportedStringSizeEncountered SdkNotAvailable "
                "HostFinderNotAvailable DataNotAvailable MemoryError InternalError FunctionCalledAtWrongTime "
                "NotConnected ConnectionTimeout InvalidID NullPointer InvalidSequence NoCoordinateSystemSet "
                "SdkIsTerminating StubNullPointer SkeletonNotLoaded FunctionNotAvailable").split()  # fmt: skip
NOT_CONNECTED, SIDE_LEFT, SIDE_RIGHT = 11, 1, 2  # SDKReturnCode_NotConnected; Side_Left, Side_Right


class ErgonomicsData(C.Structure):  # data: ErgonomicsDataType_MAX_SIZE floats
    _fields_ = [("id", C.c_uint32), ("isUserID", C.c_bool), ("data", C.c_float * 40)]


class ErgonomicsStream(C.Structure):  # publishTime is a ManusTimestamp: struct { uint64_t time; }
    _fields_ = [("publishTime", C.c_uint64), ("data", ErgonomicsData * 32), ("dataCount", C.c_uint32)]


# manusCoreVersion (never read): Version { uint32 major, minor, patch; char[16] x 3 }
class ManusHost(C.Structure):
    _fields_ = [("hostName", C.c_char * 256), ("ipAddress", C.c_char * 40), ("manusCoreVersion", C.c_uint32 * 15)]


class CoordinateSystemVUH(C.Structure):  # AxisView, AxisPolarity, Side (C enums: int), unit scale in m
    _fields_ = [("view", C.c_int), ("up", C.c_int), ("handedness", C.c_int), ("unitScale", C.c_float)]


class GloveLandscapeHead(C.Structure):
    # GloveLandscapeData begins id, classType, familyType, side; the rest (about 300 bytes, grown across SDK
    # versions) is room the call may fill, never read here.
    _fields_ = [("id", C.c_uint32), ("classType", C.c_int), ("familyType", C.c_int), ("side", C.c_int),
                ("rest", C.c_uint8 * 4096)]  # fmt: skip


ERGONOMICS_CB = C.CFUNCTYPE(None, C.POINTER(ErgonomicsStream))
HOST_CB = C.CFUNCTYPE(None, C.POINTER(ManusHost))
SIGNATURES = {
    "CoreSdk_InitializeIntegrated": [], "CoreSdk_InitializeCore": [], "CoreSdk_ShutDown": [],
    "CoreSdk_RegisterCallbackForOnConnect": [HOST_CB], "CoreSdk_RegisterCallbackForOnDisconnect": [HOST_CB],
    "CoreSdk_RegisterCallbackForErgonomicsStream": [ERGONOMICS_CB],
    "CoreSdk_InitializeCoordinateSystemWithVUH": [CoordinateSystemVUH, C.c_bool],
    "CoreSdk_LookForHosts": [C.c_uint32, C.c_bool],
    "CoreSdk_GetNumberOfAvailableHostsFound": [C.POINTER(C.c_uint32)],
    "CoreSdk_GetAvailableHostsFound": [C.POINTER(ManusHost), C.c_uint32],
    "CoreSdk_ConnectToHost": [ManusHost],
    "CoreSdk_GetDataForGlove_UsingGloveId": [C.c_uint32, C.POINTER(GloveLandscapeHead)],
}  # fmt: skip


class ManusSdk:
    """The SDK session (ManusSDK.h): initialise, register the callbacks, set a coordinate system, connect, then
    hand each ergonomics stream to the poll loop. The SDK calls back on its own threads: the callbacks only copy
    and flag; the main thread does the sending."""

    def __init__(self, cfg: BridgeConfig):
        self.cfg = cfg
        default = "libManusSDK_Integrated.so" if cfg.sdk_mode == "integrated" else "libManusSDK.so"
        self.path = path = cfg.sdk_library or os.environ.get("MANUS_SDK_LIBRARY") or default
        try:
            self.lib = C.CDLL(path)
        except OSError as e:
            raise BridgeError(f"cannot load the MANUS SDK library {path!r} ({e}): pass --sdk_library=<path to "
                              f"{default} from MANUS's SDK download> or set MANUS_SDK_LIBRARY") from None  # fmt: skip
        self._latest, self._lock = ErgonomicsStream(), threading.Lock()
        self.fresh, self.lost, self.sides, self.initialized = threading.Event(), threading.Event(), {}, False
        # Kept on self: the SDK holds only the C pointers, and a collected CFUNCTYPE object would crash it.
        self._callbacks = (ERGONOMICS_CB(self._on_ergonomics), HOST_CB(self._on_connect), HOST_CB(self._on_lost))

    def call(self, name: str, *args, ok=(0,)) -> int:
        fn = getattr(self.lib, name, None)
        if fn is None:
            hint = " (with --glove_id=<id> the bridge does not ask)" if "GetDataForGlove" in name else ""
            raise BridgeError(f"the MANUS SDK library {self.path!r} has no {name}{hint}: not the MANUS SDK, or a "
                              "version whose API differs from the ManusSDK.h this bridge follows")  # fmt: skip
        fn.argtypes, fn.restype = SIGNATURES[name], C.c_int
        code = fn(*args)
        if code not in ok:
            why = RETURN_CODES[code] if 0 <= code < len(RETURN_CODES) else "unknown"
            raise BridgeError(f"{name} returned {code} (SDKReturnCode_{why})")
        return code

    def _on_ergonomics(self, stream) -> None:
        with self._lock:
            C.memmove(C.addressof(self._latest), stream, C.sizeof(ErgonomicsStream))
        self.fresh.set()

    def _on_connect(self, host) -> None:
        logger.info("MANUS SDK connected to %s.", host.contents.hostName.decode(errors="replace") or "integrated")

    def _on_lost(self, _host) -> None:
        self.lost.set()

    def start(self) -> None:
        self.call(
            "CoreSdk_InitializeIntegrated" if self.cfg.sdk_mode == "integrated" else "CoreSdk_InitializeCore"
        )
        self.initialized = True
        ergo, on_connect, on_lost = self._callbacks
        self.call("CoreSdk_RegisterCallbackForOnConnect", on_connect)
        self.call("CoreSdk_RegisterCallbackForOnDisconnect", on_lost)
        self.call("CoreSdk_RegisterCallbackForErgonomicsStream", ergo)
        # Ergonomics are angles, whatever the frame; the SDK refuses to connect without one (NoCoordinateSystemSet).
        # X from the viewer, Z up, right-handed, metres: MANUS's minimal client's choice.
        self.call("CoreSdk_InitializeCoordinateSystemWithVUH", CoordinateSystemVUH(3, 6, SIDE_RIGHT, 1.0), True)
        self.connect()

    def connect(self) -> None:
        """Connect, retrying while there is no host yet (Core not started, dongle not plugged)."""
        deadline = time.monotonic() + self.cfg.connect_timeout_s
        while (why := self._connect_once()) is not None:
            if time.monotonic() > deadline:
                raise BridgeError(f"no MANUS host to connect to within {self.cfg.connect_timeout_s:.0f} s: {why}")
            logger.info("Waiting for a MANUS host: %s.", why)
            time.sleep(1.0)

    def _connect_once(self) -> str | None:
        """None when connected, else why not."""
        if self.cfg.sdk_mode == "integrated":
            chosen = ManusHost()  # an empty host: the SDK's own integrated Core, as ManusHost_Init makes it
            init = getattr(self.lib, "ManusHost_Init", None)
            if init is not None:
                init.argtypes, init.restype = [C.POINTER(ManusHost)], None
                init(C.byref(chosen))
        else:
            self.call("CoreSdk_LookForHosts", 1, False)
            n = C.c_uint32()
            self.call("CoreSdk_GetNumberOfAvailableHostsFound", C.byref(n))
            if not n.value:
                return "CoreSdk_LookForHosts found no MANUS Core on the network"
            hosts = (ManusHost * n.value)()
            self.call("CoreSdk_GetAvailableHostsFound", hosts, n.value)
            names = {h.hostName.decode(errors="replace"): h for h in hosts}
            names.update({h.ipAddress.decode(errors="replace"): h for h in hosts})
            if self.cfg.sdk_host and self.cfg.sdk_host not in names:
                return f"--sdk_host={self.cfg.sdk_host} is not among the hosts found: {sorted(names)}"
            chosen = names[self.cfg.sdk_host] if self.cfg.sdk_host else hosts[0]
        code = self.call("CoreSdk_ConnectToHost", chosen, ok=(0, NOT_CONNECTED))
        return None if code == 0 else "CoreSdk_ConnectToHost returned 11 (SDKReturnCode_NotConnected)"

    def side_of(self, glove_id: int) -> str | None:
        """The glove's hand, asked once per glove; None while the SDK's landscape does not know it yet."""
        if self.cfg.glove_id:
            return self.cfg.side if glove_id == self.cfg.glove_id else "other"
        if glove_id not in self.sides:
            head = GloveLandscapeHead()
            if self.call("CoreSdk_GetDataForGlove_UsingGloveId", glove_id, C.byref(head), ok=(0, 7)) != 0:
                return None  # SDKReturnCode_DataNotAvailable: the landscape has not listed it yet
            self.sides[glove_id] = {SIDE_LEFT: "left", SIDE_RIGHT: "right"}.get(head.side, "other")
            logger.info("MANUS glove %#x is the %s hand.", glove_id, self.sides[glove_id])
        return self.sides[glove_id]

    def poll(self, timeout: float) -> list[tuple[str, list[float]]]:
        """(side, the 40 ergonomics values) of each glove in the newest stream; [] if none came within `timeout`."""
        if not self.fresh.wait(timeout):
            return []
        with self._lock:
            stream = ErgonomicsStream.from_buffer_copy(self._latest)
            self.fresh.clear()
        out = []
        for d in stream.data[: min(stream.dataCount, len(stream.data))]:
            side = None if d.isUserID else self.side_of(d.id)  # a user's entry is not one glove's
            if side is not None:
                out.append((side, list(d.data)))
        return out

    def stop(self) -> None:
        """Unregister the callbacks, so that no SDK thread calls into a closing Python, then shut the SDK down."""
        if not self.initialized:
            return
        for name in ("CoreSdk_RegisterCallbackForErgonomicsStream", "CoreSdk_RegisterCallbackForOnConnect",
                     "CoreSdk_RegisterCallbackForOnDisconnect", "CoreSdk_ShutDown"):  # fmt: skip
            try:
                self.call(name, *([SIGNATURES[name][0]()] if "Register" in name else []))  # a NULL callback
            except BridgeError as e:
                logger.warning("At shutdown: %s", e)


def from_sdk(cfg: BridgeConfig, bridge: GloveBridge) -> None:
    sdk = ManusSdk(cfg)
    try:
        sdk.start()
        logger.info("Bridging the MANUS SDK's %s hand to udp://%s:%d, session %s.", cfg.side, cfg.host, cfg.port,
                    bridge.sender.session)  # fmt: skip
        next_status = time.monotonic() + cfg.status_every_s
        while True:
            for side, values in sdk.poll(0.2):  # side "other": a glove of neither hand (skipped, counted)
                bridge.deliver(
                    side, {c.name: values[c.enum_value(side)] for c in CHANNELS} if side in SIDES else {}
                )
            if sdk.lost.is_set():
                sdk.lost.clear()
                logger.warning("MANUS SDK disconnected: reconnecting.")
                sdk.connect()
            if cfg.status_every_s > 0 and time.monotonic() >= next_status:
                next_status += cfg.status_every_s
                logger.info("%s", bridge.status())
    finally:
        sdk.stop()


# --- the command line --------------------------------------------------------------------------------------------
def parse_args(argv: list[str] | None = None) -> BridgeConfig:
    p = argparse.ArgumentParser(prog="manus_bridge.py", description=(__doc__ or "").split("\n\n")[0])
    try:  # each BridgeConfig field's comment is its help, for draccus and for argparse alike
        helps = {name: text for text, name in re.findall(r"# (.+)\n\s+(\w+):", inspect.getsource(BridgeConfig))}
    except OSError:  # no source to read (a frozen or byte-compiled copy): help without the texts
        helps = {}
    for f in fields(BridgeConfig):
        default = f.default_factory() if callable(f.default_factory) else f.default
        kind = (
            (lambda s: [t for t in s.strip("[]").split(",") if t]) if isinstance(default, list) else type(default)
        )
        p.add_argument(
            f"--{f.name}", type=kind, default=default, help=f"{helps.get(f.name, '')} (default: %(default)s)"
        )
    try:
        return BridgeConfig(**vars(p.parse_args(argv)))
    except ValueError as e:
        p.error(str(e))


@contextlib.contextmanager
def _sigterm_as_interrupt():
    """SIGTERM (systemd, docker stop) ends the bridge like Ctrl-C: through its one clean-up path."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def serve_bridge(cfg: BridgeConfig) -> None:
    """Run `cfg` as a program: log to stderr, stop cleanly on SIGINT/SIGTERM, exit 2 with the reason on an error."""
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s")
    try:
        with _sigterm_as_interrupt():
            run_bridge(cfg)
    except KeyboardInterrupt:
        logger.info("Stopped.")
    except BridgeError as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(2) from None


def main(argv: list[str] | None = None) -> None:
    serve_bridge(parse_args(argv))


if __name__ == "__main__":
    main()
