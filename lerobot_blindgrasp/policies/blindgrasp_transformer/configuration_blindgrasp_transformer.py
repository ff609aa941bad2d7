"""Configuration of the `blindgrasp_transformer` student policy (paper Sec. III-B, Table IV).

The student is robomimic's BC-Transformer as the paper uses it: one token per 20 Hz step built from
o_t = 9 joint positions + 3 uniaxial forces, a causal GPT over the last 30 steps, and an MLP head that predicts
delta-theta / 0.3 in [-1, 1] from the last token. The preprocessor turns the dataset's absolute targets into those
and `select_action` turns the prediction back into a target (`processor_blindgrasp_transformer.py`), so the network
only ever sees normalized deltas.

Table IV -> field:
    batch size 256                      -> lerobot-train `--batch_size=256` (a training-loop setting)
    number of epochs 2000               -> lerobot-train `--steps` = 2000 * ceil(num_frames / batch_size), computed
                                           from the collected dataset (`lerobot_blindgrasp.presets.student`)
    optimizer AdamW, lr 1e-4            -> `optimizer_lr`
    L2 regularization 0.01              -> `optimizer_weight_decay`
    lr schedule: linear decay after
      100 epochs                        -> `scheduler_constant_steps` (= 100 epochs' worth of steps),
                                           `scheduler_end_factor`
    loss: MSE                           -> `BlindgraspTransformerPolicy.forward`
    Transformer layers 6                -> `n_layers`   (via `size="paper"`)
    embedding dimension 512             -> `embed_dim`  (via `size="paper"`)
    attention heads 8                   -> `n_heads`    (via `size="paper"`)
    context length 30 / frame stack 30  -> `n_obs_steps`
    dropout rate 0.1                    -> `dropout`
    activation GELU                     -> the transformer MLP (fixed)
    MLP head [1024, 1024]               -> `head_hidden_dims` (via `size="paper"`)

Sizes. `size` picks the architecture from `SIZES` below (the preset registry's student stages name these
sizes); any of `n_layers`, `embed_dim`, `n_heads`, `head_hidden_dims` given
explicitly wins over the preset. The resolved numbers are what `config.json` stores, so a
checkpoint reloads with the exact architecture it was trained with.
    --policy.size=paper   (default) Table IV, ~1.1 GFLOP per control step; `cpu` and `quick` are smaller
    e.g. `--policy.size=cpu --policy.n_layers=2` for a cpu-size model with 2 layers.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from lerobot.configs import FeatureType, NormalizationMode, PreTrainedConfig
from lerobot.optim import AdamWConfig
from lerobot.optim.schedulers import LRSchedulerConfig
from lerobot.utils.constants import ACTION, OBS_STATE
from torch.optim import Optimizer
from torch.optim.lr_scheduler import LambdaLR

from lerobot_blindgrasp import policy_contract, spec

# What `--policy.size` picks from; `paper` is Table IV. Defined here, with the policy, so that loading the policy
# (plugin discovery, the real gripper) never imports the preset registry and the simulator behind it.
SIZES: dict[str, dict] = {
    "paper": {"n_layers": 6, "embed_dim": 512, "n_heads": 8, "head_hidden_dims": [1024, 1024]},  # Table IV
    "cpu": {"n_layers": 3, "embed_dim": 128, "n_heads": 4, "head_hidden_dims": [256, 256]},
    "quick": {"n_layers": 2, "embed_dim": 64, "n_heads": 4, "head_hidden_dims": [128, 128]},
}


@LRSchedulerConfig.register_subclass("blindgrasp_constant_then_linear")
@dataclass
class ConstantThenLinearDecaySchedulerConfig(LRSchedulerConfig):
    """lr x 1 for `num_constant_steps`, then linear down to lr x `end_factor` at the last training step.

    LeRobot ships no such schedule. Built by lerobot-train with `num_training_steps = --steps`.
    """

    num_warmup_steps: int | None = None  # base-class field; the paper uses no warmup
    num_constant_steps: int | None = None  # None: constant for the whole run
    end_factor: float = 0.1

    def build(self, optimizer: Optimizer, num_training_steps: int) -> LambdaLR:
        constant, end = self.num_constant_steps, self.end_factor
        if constant is None:
            constant = num_training_steps

        def lr_lambda(step: int) -> float:
            if step < constant:
                return 1.0
            frac = min(1.0, (step - constant) / max(1, num_training_steps - constant))
            return 1.0 + (end - 1.0) * frac

        return LambdaLR(optimizer, lr_lambda, -1)


# What this policy's action means once its postprocessor has run: the processors turn the dataset's absolute
# targets into the network's deltas and back (`processor_blindgrasp_transformer.py`).
ACTION_MEANING = policy_contract.ACTION_MEANING


@dataclass
class TrainedFor:
    """The robot a checkpoint was trained for, read from its training dataset's metadata (`meta/info.json`: robot
    type, fps, the names of `observation.state` and `action`, in order) and the policy's own action meaning.
    `source` says where the facts were read. The real gripper refuses a checkpoint whose facts differ from its own,
    or that has none, before any servo takes torque (`policy_contract.py`)."""

    robot_type: str | None = None
    fps: float | None = None
    state_names: list[str] | None = None  # None: the dataset's metadata named no features
    action_names: list[str] | None = None
    action_meaning: str = ACTION_MEANING
    source: str | None = None

    @classmethod
    def from_dataset(cls, meta, source: str | None = None) -> TrainedFor:
        """From a `LeRobotDatasetMetadata` (or anything with `robot_type`, `fps`, `features` and `repo_id`)."""
        return cls(**policy_contract.facts_from_dataset(meta, source))


@PreTrainedConfig.register_subclass("blindgrasp_transformer")
@dataclass
class BlindgraspTransformerConfig(PreTrainedConfig):
    """See the module docstring for the Table IV mapping and the size presets."""

    # Context length = frame stacking length (Table IV: 30): the policy sees (o_{t-29}, ..., o_t).
    n_obs_steps: int = 30

    # Architecture. None -> taken from SIZES[size] in __post_init__.
    size: str = "paper"
    n_layers: int | None = None
    embed_dim: int | None = None
    n_heads: int | None = None
    head_hidden_dims: list[int] | None = None
    # One rate for robomimic's three dropouts (embedding, attention weights, block outputs); Table IV gives one.
    dropout: float = 0.1
    # robomimic's deterministic BC-Transformer squashes the action output with tanh (targets lie in [-1, 1]).
    tanh_output: bool = True

    # State: z-scored with dataset stats. Action: IDENTITY here because the action is scaled by the 0.3 rad bound
    # in the blindgrasp target->delta processor step, not by dataset stats (must stay IDENTITY, see validation).
    normalization_mapping: dict[str, NormalizationMode] = field(
        default_factory=lambda: {
            "STATE": NormalizationMode.MEAN_STD,
            "ACTION": NormalizationMode.IDENTITY,
        }
    )

    # Training (Table IV). The batch size of 256 is lerobot-train's `--batch_size=256`.
    optimizer_lr: float = 1e-4
    optimizer_betas: tuple[float, float] = (0.9, 0.999)
    optimizer_eps: float = 1e-8
    optimizer_weight_decay: float = 0.01
    # Not in the paper; LeRobot's AdamW default. 0 disables clipping.
    optimizer_grad_clip_norm: float = 10.0
    # "Linear decay after 100 epochs": constant lr for this many optimizer steps, then linear decay to
    # `scheduler_end_factor` x lr at the last step (`--steps`). An epoch's steps depend on the dataset, so there is
    # no fixed default: None keeps the lr constant for the whole run, and `blindgrasp-pipeline --preset=paper`
    # passes 100 * ceil(num_frames / batch_size) of the dataset it collected (`lerobot_blindgrasp.presets.student`).
    # End factor 0.1 is robomimic's LinearLR end factor in its BC-Transformer template.
    scheduler_constant_steps: int | None = None
    scheduler_end_factor: float = 0.1

    # Training-time sensor errors (beyond the paper; 0 = off, the paper's recipe), per sample over its window, in the
    # preprocessor's `blindgrasp_sensor_augment` step: force gain error (g in [1/(1+x), 1+x]), force offset (+-N)
    # and joint calibration offset (+-rad per joint). They teach the student the real sensors' errors the sim's
    # Gaussian noise does not have. The step is built with the processors: `--policy.path` fine-tuning reuses the
    # checkpoint's saved processors, so it keeps the augmentation its checkpoint was trained with and cannot add one.
    augment_force_gain: float = 0.0
    augment_force_bias_n: float = 0.0
    augment_joint_offset_rad: float = 0.0

    # The robot this policy was trained for (`TrainedFor`), filled from the training dataset's metadata when
    # lerobot-train builds the policy (`make_policy` hands the policy the dataset's metadata; fine-tuning on another
    # dataset replaces it) and saved in config.json. None: not recorded (a checkpoint from before it was).
    trained_for: TrainedFor | None = None

    @property
    def augmentation_active(self) -> bool:
        return max(self.augment_force_gain, self.augment_force_bias_n, self.augment_joint_offset_rad) > 0

    def __post_init__(self):
        super().__post_init__()
        if self.size not in SIZES:
            raise ValueError(f"size must be one of {sorted(SIZES)}, got {self.size!r}")
        for name, value in SIZES[self.size].items():
            if getattr(self, name) is None:
                setattr(self, name, list(value) if isinstance(value, list) else value)
        if self.embed_dim % self.n_heads != 0:
            raise ValueError(f"embed_dim ({self.embed_dim}) must be divisible by n_heads ({self.n_heads})")
        if min(self.augment_force_gain, self.augment_force_bias_n, self.augment_joint_offset_rad) < 0:
            raise ValueError("augment_* ranges must be >= 0")
        if self.n_obs_steps < 1:
            raise ValueError(f"n_obs_steps (context length) must be >= 1, got {self.n_obs_steps}")
        action_mode = self.normalization_mapping.get("ACTION", NormalizationMode.IDENTITY)
        if NormalizationMode(action_mode) is not NormalizationMode.IDENTITY:
            raise ValueError(
                "normalization_mapping['ACTION'] must be IDENTITY: actions are scaled by the 0.3 rad bound in the "
                "policy's target->delta processor step; dataset stats of absolute targets do not apply to deltas."
            )

    @property
    def observation_delta_indices(self) -> list[int]:
        return list(range(1 - self.n_obs_steps, 1))

    @property
    def action_delta_indices(self) -> None:
        # One action per step, supervised on the last token only (robomimic supervise_all_steps=False).
        return None

    @property
    def reward_delta_indices(self) -> None:
        return None

    def get_optimizer_preset(self) -> AdamWConfig:
        return AdamWConfig(
            lr=self.optimizer_lr,
            betas=self.optimizer_betas,
            eps=self.optimizer_eps,
            weight_decay=self.optimizer_weight_decay,
            grad_clip_norm=self.optimizer_grad_clip_norm,
        )

    def get_scheduler_preset(self) -> ConstantThenLinearDecaySchedulerConfig:
        return ConstantThenLinearDecaySchedulerConfig(
            num_constant_steps=self.scheduler_constant_steps, end_factor=self.scheduler_end_factor
        )

    def validate_features(self) -> None:
        state = self.input_features.get(OBS_STATE) if self.input_features else None
        if state is None or state.type is not FeatureType.STATE or tuple(state.shape) != (spec.STATE_DIM,):
            raise ValueError(
                f"blindgrasp_transformer needs input '{OBS_STATE}' of shape ({spec.STATE_DIM},) "
                f"(names {list(spec.STATE_NAMES)}), got {state}"
            )
        action = self.output_features.get(ACTION) if self.output_features else None
        if action is None or tuple(action.shape) != (spec.ACTION_DIM,):
            raise ValueError(
                f"blindgrasp_transformer needs output '{ACTION}' of shape ({spec.ACTION_DIM},) "
                f"(absolute joint targets {list(spec.ACTION_NAMES)}), got {action}"
            )
