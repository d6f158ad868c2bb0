"""The configuration as commented YAML: what ``--print-config`` prints and
``configs/default.yaml`` holds. The comments come from the schema's key documentation, so they
never drift from the code; the text loads back to the same configuration."""

from __future__ import annotations

import dataclasses
import json
import textwrap
from typing import Any

import yaml

from ndt_cli.config.schema import Config

_WIDTH = 96


def _value(v: Any) -> str:
    """One YAML scalar or flow list, as ``yaml.safe_load`` reads it back."""
    if isinstance(v, tuple | list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, str):
        return json.dumps(v)  # a double-quoted YAML string
    return yaml.safe_dump(v, default_flow_style=True).strip().removesuffix("...").strip()


def _comment(text: str, indent: str) -> list[str]:
    return textwrap.wrap(
        text, _WIDTH, initial_indent=f"{indent}# ", subsequent_indent=f"{indent}# "
    )


def _surveyor_keys(cfg: Config) -> list[str]:
    return [
        f"{s.name}.{f.name}"
        for s in dataclasses.fields(cfg)
        for f in dataclasses.fields(getattr(cfg, s.name))
        if f.metadata.get("surveyor")
    ]


def commented_yaml(cfg: Config, origin: str = "the defaults") -> str:
    """YAML text of ``cfg`` with every section and key explained in comments."""
    head = (
        f"ndt-cli configuration: {origin}. Units: metres and degrees. Every key is optional; "
        "unknown keys, wrong types and impossible values are errors naming the key. Keys a "
        f"surveyor sets: {', '.join(_surveyor_keys(cfg))}. Every other key is a method internal: "
        "change it only for a reason you have measured."
    )
    lines = _comment(head, "")
    for section in dataclasses.fields(cfg):
        values = getattr(cfg, section.name)
        lines += ["", f"{section.name}:"]
        lines += _comment(" ".join((type(values).__doc__ or "").split()), "  ")
        for f in dataclasses.fields(values):
            lines += _comment(f.metadata.get("doc", ""), "  ")
            lines.append(f"  {f.name}: {_value(getattr(values, f.name))}")
    return "\n".join(lines) + "\n"
