"""Configuration: nested, typed sections with defaults, loaded from YAML.

Unknown keys, wrong types and impossible values raise :class:`~ndt_cli.errors.ConfigError`
naming the key. ``configs/default.yaml`` documents every key with its unit.
"""

from ndt_cli.config.loading import dump, from_dict, load
from ndt_cli.config.rules import axes_matrix
from ndt_cli.config.schema import (
    Config,
    GridConfig,
    GroundConfig,
    InputConfig,
    OptimizerConfig,
    OptimizerName,
    QualityConfig,
    RefineConfig,
    SearchConfig,
    SlicesConfig,
    SourceConfig,
)

__all__ = [
    "Config",
    "GridConfig",
    "GroundConfig",
    "InputConfig",
    "OptimizerConfig",
    "OptimizerName",
    "QualityConfig",
    "RefineConfig",
    "SearchConfig",
    "SlicesConfig",
    "SourceConfig",
    "axes_matrix",
    "dump",
    "from_dict",
    "load",
]
