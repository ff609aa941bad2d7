"""`blindgrasp_transformer`: the paper's transformer student as a LeRobot policy. Importing this package registers
`--policy.type=blindgrasp_transformer` and its processor steps, and installs its data path (`window_cache`).
"""

from .configuration_blindgrasp_transformer import BlindgraspTransformerConfig
from .modeling_blindgrasp_transformer import BlindgraspTransformerPolicy
from .processor_blindgrasp_transformer import make_blindgrasp_transformer_pre_post_processors
from .window_cache import install_window_cache as _install_window_cache

_install_window_cache()

__all__ = [
    "BlindgraspTransformerConfig",
    "BlindgraspTransformerPolicy",
    "make_blindgrasp_transformer_pre_post_processors",
]
