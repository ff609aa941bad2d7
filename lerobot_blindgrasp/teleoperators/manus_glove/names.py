"""The one table of glove ergonomics names: MANUS SDK, MANUS ROS 2 publisher, and this receiver's channels.

The MANUS Core SDK reports ergonomics as `ErgonomicsData.data[ErgonomicsDataType_MAX_SIZE]` (40 floats, degrees),
indexed by the C enum `ErgonomicsDataType` of `ManusSDKTypes.h`: `ErgonomicsDataType_LeftFingerThumbMCPSpread` = 0
... `ErgonomicsDataType_LeftFingerPinkyDIPStretch` = 19, then the same 20 for `RightFinger` (20 ... 39), in the
order Thumb, Index, Middle, Ring, Pinky x MCPSpread, MCPStretch, PIPStretch, DIPStretch.

A channel here is the enum name without `ErgonomicsDataType_` and the side (`IndexMCPSpread`). The MANUS ROS 2
publisher (`manus_data_publisher`, `ErgonomicsDataTypeToString`) sends the same names as side-less strings in
`ManusGlove.ergonomics[].type`, except that it drops "MCP" from the four finger spreads (`IndexSpread`,
`MiddleSpread`, `RingSpread`, `PinkySpread`; the thumb keeps `ThumbMCPSpread`). Some public copies of the publisher
skip the index spread or send it as "Invalid": those datagrams lack `IndexMCPSpread` and are reported by name.

A datagram may key a value by any of: the channel (`IndexMCPSpread`), the ROS 2 string (`IndexSpread`), or the SDK
enum name with its side (`RightFingerIndexMCPSpread`, `ErgonomicsDataType_RightFingerIndexMCPSpread`). docs/glove.md
prints this table; a test keeps the two equal.
"""

from __future__ import annotations

from dataclasses import dataclass

FINGERS = ("Thumb", "Index", "Middle", "Ring", "Pinky")
MOTIONS = ("MCPSpread", "MCPStretch", "PIPStretch", "DIPStretch")
SIDES = ("left", "right")
ENUM_PREFIX = "ErgonomicsDataType_"


@dataclass(frozen=True)
class Channel:
    name: str  # this receiver's key: the SDK enum name without prefix and side
    finger: str
    motion: str
    ros2: str  # the MANUS ROS 2 publisher's ManusErgonomics.type string

    def enum_name(self, side: str) -> str:
        return f"{ENUM_PREFIX}{side.capitalize()}Finger{self.name}"

    def enum_value(self, side: str) -> int:
        return SIDES.index(side) * len(CHANNELS) + CHANNELS.index(self)


def _ros2_string(finger: str, motion: str) -> str:
    return f"{finger}Spread" if motion == "MCPSpread" and finger != "Thumb" else f"{finger}{motion}"


CHANNELS: tuple[Channel, ...] = tuple(
    Channel(f"{f}{m}", f, m, _ros2_string(f, m)) for f in FINGERS for m in MOTIONS
)
BY_NAME = {c.name: c for c in CHANNELS}


def _aliases() -> dict[str, tuple[str, str | None]]:
    """Every accepted key -> (channel, side it names or None)."""
    out: dict[str, tuple[str, str | None]] = {}
    for c in CHANNELS:
        out[c.name] = (c.name, None)
        out[c.ros2] = (c.name, None)
        for side in SIDES:
            full = c.enum_name(side)
            out[full] = (c.name, side)
            out[full.removeprefix(ENUM_PREFIX)] = (c.name, side)
    return out


ALIASES = _aliases()


def canonical(values: dict, side: str) -> tuple[dict[str, object], list[str]]:
    """Re-key `values` by channel name. Returns (values by channel, problems). Unknown keys are ignored (the
    publisher may add "Invalid" or channels we do not use). A key naming the other hand, or two keys for one
    channel with different values, is a problem: the datagram cannot be trusted."""
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
