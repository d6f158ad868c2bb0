"""Loading a configuration from YAML or a nested dict, and writing it back as YAML.

Unknown keys, wrong types and impossible values raise :class:`~ndt_cli.errors.ConfigError`
naming the key.
"""

from __future__ import annotations

from pathlib import Path

import yaml

from ndt_cli.config.schema import Config, from_dict
from ndt_cli.errors import ConfigError, read_user_text


def load(path: str | Path | None) -> Config:
    """Read a YAML config file (``None`` gives the defaults)."""
    if path is None:
        return Config()
    p = Path(path)
    text = read_user_text(p, "config", ConfigError)
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise ConfigError(f"invalid YAML{where}", p) from None
    if data is not None and not isinstance(data, dict):
        raise ConfigError("the config must be a mapping of sections", p)
    try:
        return from_dict(data)
    except ConfigError as exc:
        raise ConfigError(exc.message, p) from None


def dump(config: Config) -> str:
    """YAML text of ``config`` (what ``config_used.yaml`` holds)."""
    return yaml.safe_dump(config.to_dict(), sort_keys=False)
