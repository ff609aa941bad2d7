"""`blindgrasp_transformer`: the paper's transformer student as a LeRobot policy (config, model, processors).

Importing this package registers `--policy.type=blindgrasp_transformer` and its processor steps.
"""

from .configuration_blindgrasp_transformer import BlindgraspTransformerConfig
from .modeling_blindgrasp_transformer import BlindgraspTransformerPolicy
from .processor_blindgrasp_transformer import make_blindgrasp_transformer_pre_post_processors

__all__ = [
    "BlindgraspTransformerConfig",
    "BlindgraspTransformerPolicy",
    "make_blindgrasp_transformer_pre_post_processors",
]
