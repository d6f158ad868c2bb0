"""The registration report, the terminal summary and the scripts' outputs of two simulated
campaigns, as a surveyor receives them: a busy street (pedestrians, passing cars, scans 20-35 m
apart, long file names) with one scan from another street that fits nowhere, and a street with
control stations in map coordinates, one of them 60 cm off (a blunder).

Expected values come from the simulation (which scan is foreign, which station is off and by
how much, the true poses) and from what the run keeps on disk independently of the report
(one file per registration in ``links/``, ``pairs.csv``, ``poses.csv``). The pages are opened
in Debian's Chromium (skipped without it, failing under CI=true).
"""

from __future__ import annotations

import csv
import html
import io as io_text
import json
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from ndt_cli import io, sim
from ndt_cli.config import load
from ndt_cli.core.transforms import transform_errors
from ndt_cli.io.matrices import read_pose_list
from ndt_cli.pipeline.chain import run_chain
from ndt_cli.pipeline.inputs import chain_inputs
from ndt_cli.pipeline.result import ChainResult
from ndt_cli.report.chain_outputs import write_chain_outputs
from ndt_cli.report.reasons import with_named_reasons

pytestmark = pytest.mark.slow

ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
STREET = "Hauptstrasse_2024-05-17_station_{:03d}.laz"
FOREIGN = 3  # the file name's place of the scan from another street, in the campaign order
EPSG = 25832


@dataclass(frozen=True)
class Run:
    """A campaign run in this process and published as ndt-chain publishes it: its scans,
    their true T_world_scan (None: the foreign scan), its result and its output folder."""

    files: list[Path]
    truth: list[np.ndarray | None]
    result: ChainResult
    out: Path


def _run(files: list[Path], out: Path, control: Path | None = None, crs: str | None = None):
    inputs = chain_inputs(files, anchor="0", neighbours=4, adjust=True, radius=None, pairs=None,
                          control=control, crs=crs)  # fmt: skip
    cfg = load(None)
    result = run_chain(inputs.paths, cfg, out, jobs=2, network=inputs.network)
    result = with_named_reasons(result)
    write_chain_outputs(out, result, cfg, 1.0, "ndt-chain scans/*.laz --out street/")
    return result


@pytest.fixture(scope="module")
def busy(tmp_path_factory) -> Run:
    """Six scans of a busy street and, fourth in the names' order, a scan of another street."""
    folder = tmp_path_factory.mktemp("busy")
    world = sim.StreetWorld(seed=5, n_scans=6, people=20, traffic=2, spacing=(20.0, 35.0))
    _, scans, poses = sim.scan_street(world)
    _, other, _ = sim.scan_street(sim.StreetWorld(seed=99, n_scans=1))
    scans.insert(FOREIGN, other[0])
    truth: list[np.ndarray | None] = [*poses[:FOREIGN], None, *poses[FOREIGN:]]
    files = []
    for k, pts in enumerate(scans):
        files.append(folder / STREET.format(k))
        io.write(files[-1], pts)
    out = folder / "out"
    return Run(files, truth, _run(files, out), out)


@pytest.fixture(scope="module")
def control(tmp_path_factory) -> Run:
    """Six scans of a street in UTM zone 32 (on its grid); GNSS positions of three scanners
    (1 cm noise) and a fourth 60 cm east of where it stood."""
    folder = tmp_path_factory.mktemp("control")
    _, scans, poses = sim.scan_street(sim.StreetWorld(seed=51, n_scans=6))
    files = [folder / f"scan_{k}.laz" for k in range(len(scans))]
    for f, pts in zip(files, scans, strict=True):
        io.write(f, pts)
    truth = _on_the_grid(poses, np.array([500_000.0, 5_400_000.0, 100.0]))
    where = np.array([T[:3, 3] for T in truth])
    where[[0, 2, 5]] += np.random.default_rng(0).normal(0.0, [0.01, 0.01, 0.015], (3, 3))
    where[3] += [0.6, 0.0, 0.0]  # the blunder
    table = [f"{files[k].name},{x:.4f},{y:.4f},{z:.4f},0.02,0.03" for k, (x, y, z) in
             ((k, where[k]) for k in (0, 2, 5, 3))]  # fmt: skip
    stations = folder / "control.csv"
    stations.write_text("scan,x,y,z,sigma_xy,sigma_z\n" + "\n".join(table) + "\n")
    out = folder / "out"
    return Run(files, list(truth), _run(files, out, stations, f"EPSG:{EPSG}"), out)


def _on_the_grid(poses: list[np.ndarray], origin: np.ndarray) -> list[np.ndarray]:
    """The poses moved to ``origin`` (on zone 32's central meridian, 100 m up) with their
    positions on UTM's grid: ground distances times its scale there about their centre."""
    scale = 0.9996 * 6_371_000.0 / (6_371_000.0 + origin[2])
    moved = [T.copy() for T in poses]
    centre = np.mean([T[:3, 3] for T in poses], axis=0)
    for T in moved:
        T[:2, 3] = origin[:2] + centre[:2] + scale * (T[:2, 3] - centre[:2])
        T[2, 3] += origin[2]
    return moved


# ---------------------------------------------------------------- the page's parts


class _Page(HTMLParser):
    """The text of every element with an id, the rows of every data table (cell texts by
    column label) and the inspector's figures (whether each shows its picture at once)."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.tables: dict[str, list[dict[str, str]]] = {}
        self.figures: dict[str, dict[str, bool]] = {}
        self._table, self._row, self._label, self._figure = "", None, None, ""
        self._details = 0

    def handle_starttag(self, tag: str, attrs: list) -> None:
        a = dict(attrs)
        if tag == "table" and "data" in (a.get("class") or ""):
            self._table = a["id"]
            self.tables[self._table] = []
        elif tag == "tr" and self._table and self._row is None:
            self._row = {}
        elif tag == "td" and self._row is not None:
            self._label = a.get("data-label", "")
            self._row[self._label] = ""
        elif tag == "figure" and a.get("class") == "link":
            self._figure = a["id"]
            self.figures[self._figure] = {"shown": False, "on_demand": False}
        elif tag == "details":
            self._details += 1
        elif tag == "img" and self._figure:
            self.figures[self._figure]["on_demand" if self._details else "shown"] = True

    def handle_endtag(self, tag: str) -> None:
        if tag == "td":
            self._label = None
        elif tag == "tr" and self._row is not None:
            if self._row:
                self.tables[self._table].append(self._row)
            self._row = None
        elif tag == "table":
            self._table = ""
        elif tag == "figure":
            self._figure = ""
        elif tag == "details":
            self._details -= 1

    def handle_data(self, data: str) -> None:
        if self._row is not None and self._label is not None:
            self._row[self._label] += data


def _text_of(page: str, start: str, end: str) -> str:
    """The text (tags dropped, entities read) from ``start`` to the next ``end`` of ``page``."""
    part = page.split(start, 1)[1].split(end, 1)[0] if start in page else ""
    return html.unescape(re.sub(r"<[^>]+>", " ", part))


def _page(out: Path) -> _Page:
    text = (out / "report.html").read_text(encoding="utf-8")
    page = _Page()
    page.feed(text)
    page.verdict = " ".join(_text_of(text, 'id="verdict"', "</div>").split())
    page.left_out = " ".join(_text_of(text, 'id="left-out"', "</ul>").split())
    return page


def _pairs(out: Path) -> list[dict[str, str]]:
    return list(csv.DictReader((out / "pairs.csv").read_text().splitlines()))


def _registrations_on_disk(out: Path) -> int:
    """Every registration the run finished: one file each in ``links/`` (the resume store)."""
    return len(list((out / "links").glob("*.json")))


# ---------------------------------------------------------------- the report


def test_the_report_names_the_scan_left_out_and_lists_every_registration_tried(busy):
    page = _page(busy.out)
    foreign = busy.files[FOREIGN].name
    assert "Result: NOT OK" in page.verdict and foreign in page.verdict
    assert foreign in page.left_out and "registration(s) tried for it" in page.left_out
    links, tried = page.tables["links"], page.tables["tried"]
    assert len(links) + len(tried) == _registrations_on_disk(busy.out) == len(_pairs(busy.out))
    mine = [r for r in links + tried if foreign in (r["target"], r["source"])]
    assert mine and all(r["status"] != "ok" for r in mine)  # every registration of it, listed
    by_state = {row["link"]: row["network"] for row in _pairs(busy.out)}
    assert sum(r["state"] == "not checked" for r in links) == sum(
        s == "used" for s in by_state.values()
    )
    for row in links:
        if row["state"] == "not checked":  # a link no cycle checks carries no residual
            assert row["residual (cm)"] == row["residual (deg)"] == "\u2013", row
        elif row["state"] == "confirmed":
            assert re.fullmatch(r"\d+\.\d\d", row["residual (cm)"]), row


def test_every_kept_link_has_its_slices_shown_and_every_other_one_on_demand(busy, control):
    for run in (busy, control):
        page = _page(run.out)
        pairs = _pairs(run.out)
        assert len(page.figures) == sum(bool(r["tx"]) for r in pairs)  # one per transform
        for k, row in enumerate(pairs):
            figure = page.figures.get(f"link-{row['link']}")
            if row["network"] in ("confirmed", "used"):
                assert figure == {"shown": True, "on_demand": False}, (k, row["network"])
            elif row["tx"]:
                assert figure == {"shown": False, "on_demand": True}, (k, row["network"])


def test_the_report_with_control_names_the_rejected_station_and_has_its_table(control):
    page = _page(control.out)
    assert "Result: OK, with remarks" in page.verdict
    assert "control station scan_3.laz not used: rejected" in page.verdict
    rows = {r["station"]: r for r in page.tables["controls"]}
    assert set(rows) == {"scan_0.laz", "scan_2.laz", "scan_3.laz", "scan_5.laz"}
    assert rows["scan_3.laz"]["used"] == "rejected" and "chi2" in rows["scan_3.laz"]["why"]
    assert abs(float(rows["scan_3.laz"]["ΔE"]) + 60.0) < 3.0  # given 60 cm east of the truth
    for name in ("scan_0.laz", "scan_2.laz", "scan_5.laz"):
        assert rows[name]["used"] == "used"
        k = int(name[5])
        given = np.array([float(rows[name][a]) for a in ("E", "N", "h")])
        assert np.abs(given - control.truth[k][:3, 3]).max() < 0.05  # the file's numbers
        assert max(abs(float(rows[name][f"Δ{a}"])) for a in ("E", "N", "h")) < 3.0
    world = json.loads((control.out / "summary.json").read_text())["world"]
    note = (control.out / "report.html").read_text().split('id="control-note">')[1]
    assert f"{world['grid_scale']:.8f}" in note.split("</p>")[0]


# ---------------------------------------------------------------- the terminal


def _console_text(result: ChainResult, width: int) -> str:
    from rich.console import Console

    from ndt_cli.report.console import print_chain_summary

    console = Console(width=width, record=True, color_system=None, file=io_text.StringIO())
    print_chain_summary(result, console)
    return console.export_text()


@pytest.mark.parametrize("width", [80, 120])
def test_the_summary_fits_the_terminal_with_every_name_and_number_whole(busy, control, width):
    for run in (busy, control):
        text = _console_text(run.result, width)
        lines = text.splitlines()
        assert max(len(line) for line in lines) <= width
        assert "\u2026" not in text  # nothing cut to an ellipsis
        for name in run.result.names:
            assert name in text, name  # whole, on one line
        for row in _pairs(run.out):
            if row["network"] == "confirmed":
                assert f"{float(row['residual_cm']):.2f} cm" in text
        words = " ".join(text.split())  # remarks may wrap between words
        assert ("NOT OK" in words) == (run is busy)


# ---------------------------------------------------------------- scripts


def _cli(tool: str, *args: str) -> subprocess.CompletedProcess:
    code = f"from ndt_cli.cli import {tool}; {tool}()"
    return subprocess.run(
        [sys.executable, "-c", code, *args], env=ENV, capture_output=True, text=True, check=False
    )


def _resumed(run: Run, tmp_path: Path, *args: str) -> tuple[subprocess.CompletedProcess, Path]:
    """ndt-chain on a copy of the run's folder with --resume: every link taken from it."""
    out = tmp_path / "again"
    shutil.copytree(run.out, out)
    res = _cli("chain_app", *map(str, run.files), "--out", str(out), "--resume", "-j", "1", *args)
    return res, out


def test_chain_json_gives_every_scans_pose_status_cluster_and_sigma_as_the_files(busy, tmp_path):
    res, out = _resumed(busy, tmp_path, "--json")
    assert res.returncode == 1, res.stderr  # a scan is not ok
    poses = json.loads(res.stdout)["poses"]
    rows = list(csv.DictReader((out / "poses.csv").read_text().splitlines()))
    listed = read_pose_list(out / "poses.txt")
    assert [p["scan"] for p in poses] == [r["file"] for r in rows] == [f.name for f in busy.files]
    for p, row in zip(poses, rows, strict=True):
        cluster = "" if p["cluster"] is None else str(p["cluster"])
        assert p["status"] == row["status"] and cluster == row["cluster"]
        if row["has_pose"] == "true":
            T = np.array([float(row[f"m{r}{c}"]) for r in range(4) for c in range(4)])
            assert np.array_equal(np.array(p["T_world_scan"]).ravel(), T)
        else:
            assert p["T_world_scan"] is None
        if p["scan"] in listed:
            assert np.array_equal(np.array(p["T_world_scan"]), listed[p["scan"]])
        sigma = p["sigma"]
        if row["sigma_x_cm"]:
            assert f"{sigma['x_cm']:.2f}" == row["sigma_x_cm"]
            assert f"{sigma['yaw_deg']:.4f}" == row["sigma_yaw_deg"]
    foreign = poses[FOREIGN]
    assert foreign["status"] == "unposed" and foreign["T_world_scan"] is None
    assert "registration(s) tried for it" in foreign["reason"]


def test_the_log_counts_every_registration_once_and_adds_up(busy, tmp_path):
    res, out = _resumed(busy, tmp_path)
    counts = [
        tuple(map(int, m.groups()))
        for m in (re.match(r"link (\d+)/(\d+) ", ln) for ln in res.stderr.splitlines())
        if m
    ]
    n = len(_pairs(out))
    assert [k for k, _ in counts] == list(range(1, n + 1))
    assert all(k <= total for k, total in counts) and counts[-1] == (n, n)


def test_ndt_eval_judges_scans_relative_to_the_anchor_and_counts_the_unposed_one(busy, tmp_path):
    reference = tmp_path / "truth.txt"
    lines = []
    for f, T in zip(busy.files, busy.truth, strict=True):
        pose = np.eye(4) if T is None else T  # the foreign scan: any pose, it has none here
        lines.append(f"{f.name} " + " ".join(f"{v:.17g}" for v in pose.ravel()))
    identity = " ".join(f"{v:g}" for v in np.eye(4).ravel())
    lines.append(f"{STREET.format(99)} {identity}")  # a scan the result lacks
    reference.write_text("\n".join(lines) + "\n")
    res = _cli("eval_app", str(busy.out), "--gt", str(reference), "--json")
    assert res.returncode == 0, res.stderr
    ev = json.loads(res.stdout)
    assert ev["missing"] == [STREET.format(99)]
    assert ev["anchor"] == busy.files[0].name
    scans = {r["scan"]: r for r in ev["scans"]}
    assert len(scans) == len(busy.files)
    assert scans[busy.files[FOREIGN].name]["rotation_error_deg"] is None
    posed = [r for r in ev["scans"] if r["rotation_error_deg"] is not None]
    assert posed and all(r["translation_error_m"] < 0.05 for r in posed)
    rate = ev["scan_success"][0]["success_rate"]
    assert rate == pytest.approx(len(posed) / len(busy.files)) and rate < 1.0
    kept = [r for r in ev["links"] if r.get("network") in ("confirmed", "used")]
    judged = ev["success"][0]["success_rate"]
    within = [r["rotation_error_deg"] <= 2 and r["translation_error_m"] <= 0.1 for r in kept]
    assert judged == pytest.approx(np.mean(within))  # only the kept links are judged
    for name, row in scans.items():  # errors relative to the anchor, from the truth
        if row["rotation_error_deg"] is not None:
            k = [f.name for f in busy.files].index(name)
            est = read_pose_list(busy.out / "poses.txt")
            T_est = np.linalg.inv(est[busy.files[0].name]) @ est[name]
            T_ref = np.linalg.inv(busy.truth[0]) @ busy.truth[k]
            assert row["translation_error_m"] == pytest.approx(transform_errors(T_est, T_ref)[1])


# ---------------------------------------------------------------- in a real browser


def test_both_reports_fit_400_and_1024_px_and_every_figure_loads(busy, control):
    from test_html_report import CHROMIUM, LAUNCH_ARGS, _browser_or_skip

    sync_playwright = _browser_or_skip()
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=LAUNCH_ARGS)
        try:
            for run in (busy, control):
                kept = sum(r["network"] in ("confirmed", "used") for r in _pairs(run.out))
                pg = browser.new_page(viewport={"width": 1024, "height": 900})
                pg.goto((run.out / "report.html").as_uri(), wait_until="load")
                shown = pg.eval_on_selector_all(
                    "figure.link > img", "els => els.filter(i => i.naturalWidth > 0).length"
                )
                assert shown == kept
                pg.evaluate(
                    "() => document.querySelectorAll('details').forEach(d => d.open = true)"
                )
                for width in (1024, 400):
                    pg.set_viewport_size({"width": width, "height": 900})
                    sizes = pg.evaluate(
                        "() => [document.documentElement.scrollWidth, window.innerWidth,"
                        " ...[...document.images].map(i => i.complete && i.naturalWidth > 0)]"
                    )
                    assert sizes[0] <= sizes[1], (run.out, width, sizes[:2])
                    assert all(sizes[2:]) and len(sizes) > 2 + kept
                pg.close()
        finally:
            browser.close()


def test_a_link_left_unused_though_its_gate_passed_it_says_why():
    """The report adds the network's words where the link's own do not explain its state:
    rejected, ok by its gate and unused (a bridge that no bridge rule lets in), or used though
    its gate did not pass it."""
    from types import SimpleNamespace

    from ndt_cli.pipeline.verify import EdgeState
    from ndt_cli.report.reasons import network_note

    def fit(state: EdgeState) -> SimpleNamespace:
        return SimpleNamespace(state=state, reason="a bridge and no bridge is trusted")

    ok, failed = SimpleNamespace(ok=True), SimpleNamespace(ok=False)
    said = "network: a bridge and no bridge is trusted"
    assert network_note(ok, fit(EdgeState.UNUSED)) == said
    assert network_note(failed, fit(EdgeState.REJECTED)) == said
    assert network_note(failed, fit(EdgeState.UNUSED)) == ""  # its own reason says why
    assert network_note(ok, fit(EdgeState.CONFIRMED)) == ""
    assert network_note(failed, fit(EdgeState.USED)) == said  # used though its gate doubted it
    assert network_note(failed, fit(EdgeState.CONFIRMED)) == said
    assert network_note(ok, None) == ""
