"""Outputs of ``ndt-register``: the transform, the CSV report, the JSON result, the config used.

They are published together (:func:`ndt_cli.io.outdir.publish`): a failed run leaves the
previous results untouched and never a mix of old and new files.
"""

from __future__ import annotations

from pathlib import Path

from ndt_cli.config.loading import dump
from ndt_cli.config.schema import Config
from ndt_cli.io.matrices import format_matrix
from ndt_cli.io.outdir import publish
from ndt_cli.io.serialize import csv_text, to_json
from ndt_cli.ndt.result import RegistrationResult
from ndt_cli.pipeline.scans import file_hash
from ndt_cli.report.html_report import register_report
from ndt_cli.report.tables import REPORT_COLUMNS, report_row


def _with_files(result: RegistrationResult) -> dict:
    """The result's dict plus the absolute paths of its scan files and their SHA-256 (for
    ``ndt-export``; None when a file cannot be read); nothing of a scan given as an array."""
    data = result.to_dict()
    for end, name in (("target", result.target), ("source", result.source)):
        if name is not None:
            data[f"{end}_file"] = str(Path(name).resolve())
            data[f"{end}_sha256"] = file_hash(Path(name))
    return data


def register_files(result: RegistrationResult, cfg: Config) -> dict[str, str]:
    """The text outputs of a registration, by file name: the transform, the CSV report, the
    JSON result and the config used."""
    return {
        "T_target_source.txt": format_matrix(result.T_target_source),
        "report.csv": csv_text([report_row(result)], REPORT_COLUMNS),
        "result.json": to_json(_with_files(result)),
        "config_used.yaml": dump(cfg),
    }


def write_register_outputs(
    out_dir: str | Path, result: RegistrationResult, cfg: Config, command: str = ""
) -> list[Path]:
    """Publish T_target_source.txt, report.csv, result.json, config_used.yaml and report.html
    as the content of ``out_dir``, all together. ``command``: the command line that ran the
    registration, for the report ('' for a library call)."""
    out = Path(out_dir)
    text = register_files(result, cfg)
    report = register_report(result, text["config_used.yaml"], command)
    files = {**text, "report.html": report}
    publish(out, files)
    return [out / name for name in files]
