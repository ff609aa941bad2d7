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

The table itself lives in `manus_bridge.py`, the one-file bridge a lab copies to the MANUS machine, so that
the bridge and this receiver read the same names (tests/teleoperators/test_glove_standalone.py checks they are one object).
"""

from __future__ import annotations

from .manus_bridge import ALIASES, BY_NAME, CHANNELS, ENUM_PREFIX, FINGERS, MOTIONS, SIDES, Channel, canonical

__all__ = ["ALIASES", "BY_NAME", "CHANNELS", "ENUM_PREFIX", "FINGERS", "MOTIONS", "SIDES", "Channel", "canonical"]
