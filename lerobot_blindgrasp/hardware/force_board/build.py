"""Build the force board's firmware (avr-gcc, through its Makefile) and its simavr harness (the host C compiler).

    python -m lerobot_blindgrasp.hardware.force_board.build --out_dir=build/force_board --port=/dev/ttyUSB0

prints the HEX image it built and the two ways to flash it onto the Nano at `--port` (avrdude, or the firmware's
Makefile inside the installed package). The sources ship as package data; the build writes only into `out_dir`.
"""

from __future__ import annotations

import logging
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

from lerobot_blindgrasp.cli import parse_config

logger = logging.getLogger(__name__)

HERE = Path(__file__).resolve().parent
FIRMWARE_DIR = HERE / "firmware"
SIMAVR_DIR = HERE / "simavr"
SIMAVR_INCLUDE = Path("/usr/include/simavr")

# What each build needs: (Debian package, how to tell it is installed).
FIRMWARE_NEEDS = (
    ("make", lambda: shutil.which("make")),
    ("gcc-avr", lambda: shutil.which("avr-gcc") and shutil.which("avr-objcopy")),
    ("avr-libc", lambda: Path("/usr/lib/avr/include/avr/io.h").exists()),
)
SIMULATOR_NEEDS = (
    ("gcc", lambda: shutil.which("cc")),
    ("libsimavr-dev", lambda: (SIMAVR_INCLUDE / "sim_avr.h").exists()),
)


class BuildError(RuntimeError):
    """A build step failed or its toolchain is missing; the message names the Debian packages or the compiler's
    own words."""


def missing_packages(needs=FIRMWARE_NEEDS + SIMULATOR_NEEDS) -> list[str]:
    """The Debian packages that are missing for the firmware and the simulator builds (or for `needs`)."""
    return [package for package, present in needs if not present()]


def _require(needs) -> None:
    if missing := missing_packages(needs):
        raise BuildError(f"missing build tools: apt-get install {' '.join(missing)} (Debian/Ubuntu package names)")


def _run(cmd: list[str], what: str) -> None:
    done = subprocess.run(cmd, check=False, capture_output=True, text=True)
    if done.returncode:
        raise BuildError(f"{what} failed ({' '.join(cmd)}):\n{done.stdout}{done.stderr}")


def build_firmware(out_dir, baud: int = 115_200, defines: tuple[str, ...] = ()) -> Path:
    """Compile the firmware into `out_dir` with its own Makefile; returns the Intel HEX image to flash (the ELF
    lies next to it). `defines` (e.g. "VIOLATE_T2") make the tests' broken builds, never one to flash."""
    _require(FIRMWARE_NEEDS)
    out = Path(out_dir).resolve()
    out.mkdir(parents=True, exist_ok=True)
    makefile = FIRMWARE_DIR / "Makefile"
    _run(["make", "--no-print-directory", "-s", "-C", str(out), "-f", str(makefile), f"OUT={out}", f"BAUD={baud}", "DEFS=" + " ".join(f"-D{d}" for d in defines)],
         "firmware build")  # fmt: skip
    hex_path = out / "force_board.hex"
    if not hex_path.exists():
        raise BuildError(f"the firmware build made no {hex_path}")
    return hex_path


def build_simulator(out_dir) -> Path:
    """Compile the simavr harness (`simavr/hx711_sim.c`, linked with libsimavr) into `out_dir`; returns the
    executable."""
    _require(SIMULATOR_NEEDS)
    out = Path(out_dir).resolve()
    out.mkdir(parents=True, exist_ok=True)
    exe = out / "hx711_sim"
    src = SIMAVR_DIR / "hx711_sim.c"
    if exe.exists() and exe.stat().st_mtime >= src.stat().st_mtime:
        return exe  # built already (make decides the same for the firmware)
    _run(["cc", "-O2", "-Wall", "-Wextra", "-Werror", f"-I{SIMAVR_INCLUDE}", "-o", str(exe), str(src),
          "-lsimavr", "-lutil"], "simavr harness build")  # fmt: skip
    return exe


@dataclass
class BuildConfig:
    # Where the HEX/ELF (and, with --simulator=true, the simavr harness) go.
    out_dir: Path = Path("build/force_board")
    # UART baud rate; the robot's --robot.force_sensor.baudrate must match (default 115 200 on both sides).
    baud: int = 115_200
    # The Nano's serial port, for the printed flash commands (`lerobot-find-port` names it).
    port: str = "/dev/ttyUSB0"
    simulator: bool = False


def flash_commands(hex_path: Path, port: str) -> list[str]:
    """The two equivalent ways to flash `hex_path` through a Nano's bootloader: avrdude, and the Makefile's target."""
    out_dir = hex_path.parent
    return [
        f"avrdude -p m328p -c arduino -P {port} -b 115200 -U flash:w:{hex_path}:i",
        f"make -f {FIRMWARE_DIR / 'Makefile'} OUT={out_dir} flash PORT={port}",
    ]


def main(argv: list[str] | None = None) -> None:
    cfg = parse_config(BuildConfig, argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    hex_path = build_firmware(cfg.out_dir, cfg.baud)
    avrdude, make = flash_commands(hex_path, cfg.port)
    print(f"firmware: {hex_path}")
    print(f"flash it: {avrdude}")
    print(f"      or: {make}")
    print("  (a Nano with the old bootloader: avrdude -b 57600, or make BOOTLOADER_BAUD=57600)")
    if cfg.simulator:
        print(f"simulator: {build_simulator(cfg.out_dir)} {hex_path}")


if __name__ == "__main__":
    main()
