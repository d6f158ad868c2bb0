"""Loading a configuration from YAML or a nested dict, and writing it back as YAML.

Unknown keys, wrong types and impossible values raise :class:`~ndt_cli.errors.ConfigError`
naming the key.
"""

from __future__ import annotations

from pathlib import Path

import yaml

from ndt_cli.config.schema import Config, from_dict
from ndt_cli.errors import ConfigError, read_user_text

PRESETS = Path(__file__).resolve().parents[1] / "configs"  # shipped configurations


class _UniqueKeys(yaml.SafeLoader):
    """YAML loader that refuses a key given twice in one mapping (the second would win)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen: set = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if key in seen:
                raise ConfigError(f"key '{key}' given twice (line {key_node.start_mark.line + 1})")
            seen.add(key)
        return super().construct_mapping(node, deep)


def load(path: str | Path | None) -> Config:
    """Read a YAML config file, or a shipped configuration by name (``None``: the defaults)."""
    if path is None:
        return Config()
    p = resolve(path)
    text = read_user_text(p, "config", ConfigError)
    try:
        data = yaml.load(text, Loader=_UniqueKeys)
    except ConfigError as exc:
        raise ConfigError(exc.message, p) from None
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


def preset_names() -> list[str]:
    """Names of the configurations shipped with the package (``--config NAME``)."""
    return sorted(p.stem for p in PRESETS.glob("*.yaml"))


def resolve(name_or_path: str | Path) -> Path:
    """A config file: an existing path, or the name of a shipped configuration (``paper``)."""
    p = Path(name_or_path)
    if p.exists() or p.suffix or len(p.parts) > 1:
        return p
    preset = PRESETS / f"{p.name}.yaml"
    if preset.exists():
        return preset
    raise ConfigError(
        f"no config file or shipped configuration of that name (shipped: "
        f"{', '.join(preset_names())})",
        p,
    )
