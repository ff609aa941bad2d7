"""`blindgrasp-glove-bridge`: MANUS's ROS 2 publisher or the MANUS SDK -> the glove receiver's UDP datagrams.

The program of `manus_bridge.py` as this package's command, its flags parsed by draccus like every `blindgrasp-*`
command (`--topics=[manus_glove_0,manus_glove_1]`). On the MANUS machine, without this package, the same program
runs as `python3 manus_bridge.py` with the same flags (docs/glove.md).
"""

from __future__ import annotations

from lerobot_blindgrasp.cli import parse_config

from .manus_bridge import BridgeConfig, BridgeError, GloveBridge, ergonomics_from_message, run_bridge, serve_bridge

GloveBridgeConfig = BridgeConfig  # the name this command's config had before the bridge became one file
__all__ = ["BridgeError", "GloveBridge", "GloveBridgeConfig", "ergonomics_from_message", "main", "run_bridge"]


def main(argv: list[str] | None = None) -> None:
    serve_bridge(parse_config(BridgeConfig, argv))


if __name__ == "__main__":
    main()
