"""`blindgrasp-collect-demos`: roll out a trained teacher, curate its episodes and write a LeRobotDataset. The command
line of `collection_loop`: it prints the yield table and maps outcomes to exit codes."""

from __future__ import annotations

import logging
import sys

from lerobot_blindgrasp import durable
from lerobot_blindgrasp.cli import command_line, parse_config
from lerobot_blindgrasp.demos import yield_report
from lerobot_blindgrasp.demos.collection_loop import collect_demos
from lerobot_blindgrasp.demos.config import CollectConfig, CollectError

EXIT_EMPTY = 3  # the collection ran but wrote no episode
EXIT_WRITE = 4  # a write failed (full disk, quota)


def main(argv=None) -> None:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    logging.getLogger("blindgrasp").setLevel(logging.INFO)  # LeRobot's imports may have configured the root first
    cfg = parse_config(CollectConfig, argv)
    command = command_line("blindgrasp-collect-demos", argv)
    try:
        stats = collect_demos(cfg, command=command)
    except CollectError as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    except KeyboardInterrupt:
        print(f"\naborted; the dataset in {cfg.output_dir} is finalized and readable", file=sys.stderr)
        raise SystemExit(130) from None
    except (durable.WriteError, OSError) as e:  # a full disk, a quota: a clean message, not a traceback
        print(
            f"error: {e if isinstance(e, durable.WriteError) else durable.describe_write_error(e)}. Free space, then run the "
            f"same command with --resume=true: the episodes written before it are kept.",
            file=sys.stderr,
        )
        raise SystemExit(EXIT_WRITE) from None
    tally = yield_report.load_tally(cfg.output_dir)
    print(yield_report.format_table(tally, list(cfg.object_names)))
    print(
        f"\n{stats.kept} episodes written ({stats.frames} frames) from {stats.rollouts} rollouts in "
        f"{stats.wall_s / 60:.1f} min: {stats.demos_per_minute:.1f} demos/min, "
        f"{stats.demos_per_cpu_minute:.1f} demos/CPU-min; dataset: {cfg.output_dir}"
    )
    if tally.total().kept == 0 and stats.stop_reason != "interrupted":
        # LeRobot cannot load a dataset without episodes (it then tries the Hub), so stop anything downstream here.
        print(
            f"error: {cfg.output_dir} is empty: no episode met the curation criteria, so LeRobot cannot load it; "
            "use a better teacher, a larger --max_rollouts_per_object or --curation.enabled=false, with "
            "--resume=true to append",
            file=sys.stderr,
        )
        raise SystemExit(EXIT_EMPTY)
    if stats.stop_reason == "interrupted":
        again = command if cfg.resume else f"{command} --resume=true"
        print(f"interrupted; every written episode is readable. To continue: {again}", file=sys.stderr)
        raise SystemExit(130)


if __name__ == "__main__":
    main()
