"""Configuration of the `blindgrasp_transformer` student policy (paper Sec. III-B, Table IV).

robomimic's BC-Transformer as the paper uses it: a causal GPT over the last 30 o_t (9 joints + 3 forces) and an MLP
head predicting delta-theta / 0.3 in [-1, 1] from the last token (the processors convert absolute targets).

Table IV -> field:
    batch size 256                      -> lerobot-train `--batch_size=256` (a training-loop setting)
    number of epochs 2000               -> lerobot-train `--steps`, from the collected dataset (`presets.student`)
    optimizer AdamW, lr 1e-4            -> `optimizer_lr`
    L2 regularization 0.01              -> `optimizer_weight_decay`
    linear lr decay after 100 epochs    -> `scheduler_constant_steps` (100 epochs' steps), `scheduler_end_factor`
    loss: MSE                           -> `BlindgraspTransformerPolicy.forward`
    layers 6, embedding 512, heads 8    -> `n_layers`, `embed_dim`, `n_heads` (via `size="paper"`)
    MLP head [1024, 1024]               -> `head_hidden_dims` (via `size="paper"`)
    context length 30 / frame stack 30  -> `n_obs_steps`
    dropout rate 0.1                    -> `dropout`
    activation GELU                     -> the transformer MLP (fixed)

`--policy.size` (default `paper`, Table IV) picks the architecture from `SIZES`; an explicit `n_layers`,
`embed_dim`, `n_heads` or `head_hidden_dims` wins. `config.json` stores the resolved numbers.
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

# Defined with the policy, so that loading it never imports the preset registry and the simulator behind it.
SIZES: dict[str, dict] = {
    "paper": {"n_layers": 6, "embed_dim": 512, "n_heads": 8, "head_hidden_dims": [1024, 1024]},  # Table IV
    "cpu": {"n_layers": 3, "embed_dim": 128, "n_heads": 4, "head_hidden_dims": [256, 256]},
    "quick": {"n_layers": 2, "embed_dim": 64, "n_heads": 4, "head_hidden_dims": [128, 128]},
}


@LRSchedulerConfig.register_subclass("blindgrasp_constant_then_linear")
@dataclass
class ConstantThenLinearDecaySchedulerConfig(LRSchedulerConfig):
    """lr x 1 for `num_constant_steps`, then linear down to lr x `end_factor` at the last step (`--steps`); LeRobot
    ships no such schedule."""

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


@dataclass
class TrainedFor:
    """The robot a checkpoint was trained for (`policy_contract.facts_from_dataset`), which the real gripper checks
    before any servo takes torque."""

    robot_type: str | None = None
    fps: float | None = None
    state_names: list[str] | None = None  # None: the dataset's metadata named no features
    action_names: list[str] | None = None
    action_meaning: str = policy_contract.ACTION_MEANING  # what the action means once postprocessed
    source: str | None = None


@PreTrainedConfig.register_subclass("blindgrasp_transformer")
@dataclass
class BlindgraspTransformerConfig(PreTrainedConfig):
    """See the module docstring for the Table IV mapping and the size presets."""

    n_obs_steps: int = 30  # context length = frame stack (Table IV): the policy sees (o_{t-29}, ..., o_t)

    # Architecture. None -> taken from SIZES[size] in __post_init__.
    size: str = "paper"
    n_layers: int | None = None
    embed_dim: int | None = None
    n_heads: int | None = None
    head_hidden_dims: list[int] | None = None
    # One rate for robomimic's three dropouts (embedding, attention weights, block outputs); Table IV gives one.
    dropout: float = 0.1
    tanh_output: bool = True  # as robomimic's deterministic BC-Transformer (the targets lie in [-1, 1])

    # Action: IDENTITY, since the target->delta processor step scales it by the 0.3 rad bound (checked below).
    normalization_mapping: dict[str, NormalizationMode] = field(
        default_factory=lambda: {"STATE": NormalizationMode.MEAN_STD, "ACTION": NormalizationMode.IDENTITY}
    )

    optimizer_lr: float = 1e-4
    optimizer_betas: tuple[float, float] = (0.9, 0.999)
    optimizer_eps: float = 1e-8
    optimizer_weight_decay: float = 0.01
    optimizer_grad_clip_norm: float = 10.0  # not in the paper: LeRobot's AdamW default; 0 disables clipping
    # "Linear decay after 100 epochs": constant lr for this many steps (None: the whole run; epochs depend on the
    # dataset, `presets.student`), then linear to end_factor x lr (0.1: robomimic's BC-Transformer template).
    scheduler_constant_steps: int | None = None
    scheduler_end_factor: float = 0.1

    # Training-time sensor errors (beyond the paper; 0 = off): the preprocessor's `blindgrasp_sensor_augment` step.
    # `--policy.path` fine-tuning reuses the checkpoint's saved processors, so it cannot add or drop one.
    augment_force_gain: float = 0.0
    augment_force_bias_n: float = 0.0
    augment_joint_offset_rad: float = 0.0

    trained_for: TrainedFor | None = None  # set when lerobot-train builds the policy; None: not recorded

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
