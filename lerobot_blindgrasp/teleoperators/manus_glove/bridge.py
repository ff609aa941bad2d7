"""`blindgrasp-glove-bridge`: MANUS's ROS 2 publisher or the MANUS SDK -> the glove receiver's UDP datagrams.

The program of `manus_bridge.py` as this package's command, its flags parsed by draccus like every `blindgrasp-*`
command. On the MANUS machine the same program runs as `python3 manus_bridge.py` (docs/glove.md).
"""

from __future__ import annotations

from lerobot_blindgrasp.cli import parse_config

from .manus_bridge import BridgeConfig, serve_bridge


def main(argv: list[str] | None = None) -> None:
    serve_bridge(parse_config(BridgeConfig, argv))


if __name__ == "__main__":
    main()
