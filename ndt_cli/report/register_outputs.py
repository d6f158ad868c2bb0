"""Outputs of ``ndt-register``: the transform, the CSV report, the JSON result, the config used.

Every file is written atomically (temporary file, then rename): a failed run leaves the
previous results untouched and never a half-written file.
"""

from __future__ import annotations

from pathlib import Path

from ndt_cli.config.loading import dump
from ndt_cli.config.schema import Config
from ndt_cli.io import atomic
from ndt_cli.io.matrices import format_matrix
from ndt_cli.io.serialize import csv_text, to_json
from ndt_cli.ndt.result import RegistrationResult
from ndt_cli.report.tables import REPORT_COLUMNS, report_row


def write_register_outputs(
    out_dir: str | Path, result: RegistrationResult, cfg: Config
) -> list[Path]:
    """Write T_target_source.txt, report.csv, result.json and config_used.yaml into ``out_dir``."""
    out = Path(out_dir)
    files = {
        "T_target_source.txt": format_matrix(result.T_target_source),
        "report.csv": csv_text([report_row(result)], REPORT_COLUMNS),
        "result.json": to_json(result.to_dict()),
        "config_used.yaml": dump(cfg),
    }
    for name, text in files.items():
        atomic.write_text(out / name, text)
    return [out / name for name in files]
