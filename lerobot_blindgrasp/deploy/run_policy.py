"""Policy deployment on the gripper: LeRobot's rollout engine, with the fingertip forces kept in the policy input.

    blindgrasp-rollout --strategy.type=base \\
        --policy.path=<checkpoint> --robot="include robot_configs/blindgrasp_gripper.yaml" --fps=20 --duration=10

`lerobot-rollout`'s own code and flags, but LeRobot 0.6.1 keeps only `*.pos`/`*.vel` robot features, which would
feed a 9-d state to a policy trained on 12: `DeclareForceFeatures` declares the forces again.
"""

# No `from __future__ import annotations`: LeRobot's parser.wrap reads the config class from the real annotation.
import logging

from lerobot.configs import parser
from lerobot.configs.types import PipelineFeatureType
from lerobot.processor import RobotProcessorPipeline
from lerobot.processor.converters import observation_to_transition, transition_to_observation
from lerobot.processor.pipeline import ObservationProcessorStep
from lerobot.rollout import RolloutConfig, build_rollout_context, create_strategy
from lerobot.utils.import_utils import register_third_party_plugins
from lerobot.utils.process import ProcessSignalHandler
from lerobot.utils.utils import init_logging

from lerobot_blindgrasp import compat, policy_contract, spec

logger = logging.getLogger(__name__)


class DeclareForceFeatures(ObservationProcessorStep):
    """Identity on the data; adds the fingertip forces to the declared observation features."""

    def observation(self, observation):
        return observation

    def transform_features(self, features):
        obs = dict(features.get(PipelineFeatureType.OBSERVATION, {}))
        for name in spec.FORCE_FEATURE_NAMES:
            obs.setdefault(name, float)
        return {**features, PipelineFeatureType.OBSERVATION: obs}


@parser.wrap()
def rollout(cfg: RolloutConfig) -> None:
    init_logging()
    if cfg.display_data:
        logger.warning("--display_data is not supported here; run without it.")
    if cfg.policy is not None and cfg.policy.pretrained_path and cfg.robot is not None:
        # Before build_rollout_context loads the policy (its size errors never say "action") and connects the robot.
        allow = getattr(cfg.robot, "allow_unverified_policy", False)
        policy_contract.check_named(
            cfg.policy.pretrained_path, cfg.robot.type, cfg.fps, "--fps", allow_unverified=allow
        )
    signal_handler = ProcessSignalHandler(use_threads=True, display_pid=False)
    processor = RobotProcessorPipeline(
        steps=[DeclareForceFeatures()],
        to_transition=observation_to_transition,
        to_output=transition_to_observation,
    )
    ctx = build_rollout_context(cfg, signal_handler.shutdown_event, robot_observation_processor=processor)
    strategy = create_strategy(cfg.strategy)
    try:
        strategy.setup(ctx)
        strategy.run(ctx)
    except KeyboardInterrupt:
        logger.info("Interrupted by user")
    finally:
        strategy.teardown(ctx)  # returns to the start pose (unless disabled) and disconnects: torque off


def main(argv: list[str] | None = None) -> None:
    if argv is not None:
        compat.set_lerobot_argv(argv)
    register_third_party_plugins()
    rollout()


if __name__ == "__main__":
    main()
