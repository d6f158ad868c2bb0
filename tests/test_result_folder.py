"""A result folder read back for the export: statuses as the outputs write them become the
enums of the network and of a registration, and every check refuses what it must."""

from __future__ import annotations

import csv
import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from ndt_cli.errors import InputError
from ndt_cli.ndt.result import Status
from ndt_cli.pipeline.result_folder import check_scan_files, result_scans, select
from ndt_cli.pipeline.scans import file_hash
from ndt_cli.pipeline.verify import NodeStatus
from ndt_cli.report.tables import POSE_COLUMNS

MATRIX = [f"m{r}{c}" for r in range(4) for c in range(4)]


def _row(k: int, name: str, status: str, cluster: str = "0", reason: str = "") -> dict:
    posed = status != "unposed"
    row = dict.fromkeys(POSE_COLUMNS, "")
    row.update(scan=str(k), file=name, has_pose="true" if posed else "false", status=status)
    row.update(cluster=cluster if posed else "", reason=reason)
    if posed:
        row.update(zip(MATRIX, map(str, np.eye(4).ravel()), strict=True))
    return row


def _chain_folder(tmp_path: Path, rows: list[dict], hashes: list | None) -> Path:
    folder = tmp_path / "street"
    folder.mkdir()
    files = [str(tmp_path / r["file"]) for r in rows]
    summary: dict = {"scan_files": files, "anchor": 0}
    if hashes is not None:
        summary["scan_sha256"] = hashes
    (folder / "summary.json").write_text(json.dumps(summary), encoding="utf-8")
    with open(folder / "poses.csv", "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, POSE_COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    return folder


STREET = [
    _row(0, "a.laz", "ok"),
    _row(1, "b.laz", "suspect", reason="reached only through an unchecked link"),
    _row(2, "c.laz", "unposed", reason="no usable link"),
    _row(3, "d.laz", "ok", cluster="1"),
]


def test_statuses_are_read_as_the_network_s_enums(tmp_path):
    scans, anchor = result_scans(_chain_folder(tmp_path, STREET, None))
    assert anchor == 0
    assert [s.status for s in scans] == [
        NodeStatus.OK,
        NodeStatus.SUSPECT,
        NodeStatus.UNPOSED,
        NodeStatus.OK,
    ]
    assert [s.cluster for s in scans] == [0, 0, 0, 1]
    assert not any(s.hash_recorded for s in scans)


def test_only_ok_scans_of_the_anchor_s_cluster_are_exported_and_the_others_say_why(tmp_path):
    scans, _ = result_scans(_chain_folder(tmp_path, STREET, None))
    keep, left = select(scans, None, include_suspect=False)
    assert keep == [0]
    assert left == [
        "b.laz: suspect: reached only through an unchecked link (--include-suspect exports it)",
        "c.laz: unposed: no usable link",
        "d.laz: in cluster 1, not 0 (--cluster)",
    ]
    assert select(scans, None, include_suspect=True)[0] == [0, 1]
    assert select(scans, ["d.laz", "0"], include_suspect=True)[0] == [0]


def test_another_cluster_is_exported_when_named_and_a_cluster_that_is_not_is_refused(tmp_path):
    scans, _ = result_scans(_chain_folder(tmp_path, STREET, None))
    keep, left = select(scans, None, include_suspect=True, cluster=1)
    assert keep == [3]
    assert left[0] == "a.laz: in cluster 0, not 1 (--cluster)"
    assert left[2] == "c.laz: unposed: no usable link"
    with pytest.raises(InputError, match=r"--cluster 2: .* \(it has 0, 1\)"):
        select(scans, None, include_suspect=False, cluster=2)


def test_a_cluster_that_is_not_a_number_is_refused(tmp_path):
    rows = [_row(0, "a.laz", "ok"), _row(1, "b.laz", "ok", cluster="one")]
    with pytest.raises(InputError, match="cluster 'one' is not a cluster number"):
        result_scans(_chain_folder(tmp_path, rows, None))


def test_a_status_that_no_run_writes_is_refused(tmp_path):
    rows = [_row(0, "a.laz", "ok"), _row(1, "b.laz", "confirmed")]
    with pytest.raises(InputError, match="status 'confirmed' with has_pose true"):
        result_scans(_chain_folder(tmp_path, rows, None))


def test_an_unposed_scan_with_a_pose_is_refused(tmp_path):
    rows = [_row(0, "a.laz", "ok"), {**_row(1, "b.laz", "ok"), "status": "unposed"}]
    with pytest.raises(InputError, match="status 'unposed' with has_pose true"):
        result_scans(_chain_folder(tmp_path, rows, None))


def test_a_file_unreadable_when_registered_is_not_the_file_that_was(tmp_path):
    (tmp_path / "a.laz").write_bytes(b"scan a")
    (tmp_path / "b.laz").write_bytes(b"scan b")
    good = hashlib.sha256(b"scan a").hexdigest()
    rows = [_row(0, "a.laz", "ok"), _row(1, "b.laz", "ok")]
    scans, _ = result_scans(_chain_folder(tmp_path, rows, [good, None]))
    assert [(s.sha256, s.hash_recorded) for s in scans] == [(good, True), (None, True)]
    check_scan_files(scans, [0])
    with pytest.raises(InputError, match="not the file that was registered"):
        check_scan_files(scans, [1])


def test_a_result_without_hashes_is_exported_unchecked(tmp_path, caplog):
    (tmp_path / "a.laz").write_bytes(b"scan a")
    scans, _ = result_scans(_chain_folder(tmp_path, STREET, None))
    check_scan_files(scans, [0])
    assert "records no SHA-256" in caplog.text


def _pair_folder(tmp_path: Path, **fields) -> Path:
    folder = tmp_path / "pair"
    folder.mkdir()
    data = {"T_target_source": np.eye(4).tolist(), "warnings": [], **fields}
    (folder / "result.json").write_text(json.dumps(data), encoding="utf-8")
    return folder


def test_a_pair_s_statuses_are_the_registration_s(tmp_path):
    folder = _pair_folder(tmp_path, target="a.laz", source="b.laz", status="degenerate")
    scans, anchor = result_scans(folder)
    assert anchor == 0 and [s.status for s in scans] == [Status.OK, Status.DEGENERATE]
    keep, left = select(scans, None, include_suspect=True)
    assert keep == [0] and left == ["b.laz: degenerate"]


def test_a_pair_registered_from_arrays_has_no_files_to_export(tmp_path):
    folder = _pair_folder(tmp_path, target=None, source=None, status="ok")
    with pytest.raises(InputError, match="registered from arrays"):
        result_scans(folder)


def test_a_failed_pair_is_refused(tmp_path):
    folder = _pair_folder(tmp_path, target="a.laz", source="b.laz", status="failed")
    with pytest.raises(InputError, match="status 'failed' is not one of ok, degenerate"):
        result_scans(folder)


def test_a_file_that_cannot_be_read_has_no_hash(tmp_path):
    (tmp_path / "a.laz").write_bytes(b"scan a")
    assert file_hash(tmp_path / "a.laz") == hashlib.sha256(b"scan a").hexdigest()
    assert file_hash(tmp_path / "gone.laz") is None
