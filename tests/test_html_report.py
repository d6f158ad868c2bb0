"""The HTML registration report: the page's text, and the page as a real browser draws it.

The browser test opens the file in Debian's Chromium (``/usr/bin/chromium``) through
Playwright; it skips when either is missing, and fails instead when the environment variable
``CI`` is "true".
"""

from __future__ import annotations

import base64
import html
import io
import math
import os
import re
import shutil
from dataclasses import replace
from datetime import UTC, datetime
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import pytest

from ndt_cli.report.html import (
    STATUS_CLASSES,
    ControlRow,
    Figure,
    HtmlReport,
    LinkCard,
    LinkRow,
    ScanRow,
    Verdict,
    render_html,
    status_class,
)

HOSTILE = "scan_<03>&\"quoted\" 'it'.laz"
SCRIPT = '<script>alert("x")</script>'
LONG = "very_long_scan_name_without_any_break_" * 4 + ".laz"
CHROMIUM = "/usr/bin/chromium"
VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source"}
VOID |= {"track", "wbr"}


def _png() -> bytes:
    """A small synthetic figure: a colour gradient and a line plot, as PNG bytes."""
    matplotlib = pytest.importorskip("matplotlib")

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, (a, b) = plt.subplots(1, 2, figsize=(4, 2), dpi=80)
    a.imshow(np.linspace(0, 1, 400).reshape(20, 20), cmap="viridis")
    x = np.linspace(0, 10, 50)
    b.plot(x, np.sin(x), "r-", x, np.cos(x), "b--")
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return buf.getvalue()


@pytest.fixture(scope="module")
def png() -> bytes:
    """The synthetic figure, made once."""
    return _png()


def _scans() -> tuple[ScanRow, ...]:
    """12 scans: one hostile name, one very long name, one unposed, one with NaN."""
    names = [f"scan_{k:02d}.laz" for k in range(12)]
    names[3], names[7] = HOSTILE, LONG
    rows = []
    for k, name in enumerate(names):
        posed = k != 9
        rows.append(
            ScanRow(
                name=name,
                status="anchor" if k == 0 else ("ok" if posed else "unposed"),
                x_m=15.0 * k - 0.123 if posed else None,
                y_m=0.5 * k if posed else None,
                z_m=0.01 * k if posed else None,
                yaw_deg=3.25 * k if posed else None,
                sd_x_cm=0.4 + 0.1 * k if posed and k else None,
                sd_y_cm=math.nan if k == 5 else 0.3,
                sd_z_cm=0.2,
                sd_yaw_deg=0.0021,
                reason="" if posed else f"no usable link to {SCRIPT}",
            )
        )
    return tuple(rows)


def _links(scans: tuple[ScanRow, ...]) -> tuple[LinkRow, ...]:
    """Adjacent links along the street, two skips, a loop and a user link."""
    names = [s.name for s in scans]
    pairs = [("adjacent", k, k + 1) for k in range(11)] + [("skip", 2, 4), ("loop", 0, 11)]
    pairs.append(("user", 5, 8))
    statuses = ["ok", "suspect", "degenerate", "failed", "not_converged", "no_overlap"]
    states = ["not checked", "confirmed", "rejected", "not checked"]
    return tuple(
        LinkRow(
            kind=kind,
            target=names[a],
            source=names[b],
            status=statuses[i % len(statuses)],
            state=states[i % len(states)],
            score_per_point=0.61 + 0.01 * i,
            overlap=0.8 - 0.02 * i,
            ambiguity=0.35 if i % 3 else None,
            icp_rms_cm=1.2 + 0.1 * i,
            residual_deg=None if states[i % len(states)] == "not checked" else 0.0123,
            residual_cm=None if states[i % len(states)] == "not checked" else 0.87,
            warnings=(f"weak direction along the street {SCRIPT}", "overlap below 0.3")
            if i == 1
            else (),
            strength_mm=(3.2, 2.4, 4000.0 if i == 2 else 4.1),
            figure=f"link-{i}",
        )
        for i, (kind, a, b) in enumerate(pairs)
    )


def _controls() -> tuple[ControlRow, ...]:
    """Three stations in map coordinates, one of them rejected (60 cm off)."""
    return (
        ControlRow(
            HOSTILE,
            (500100.0, 5400200.0, 101.5),
            (500100.004, 5400200.01, 101.51),
            (0.4, 1.0, 1.0),
            2.0,
            3.0,
            "used",
        ),
        ControlRow(
            "scan_05.laz",
            (500160.6, 5400210.0, 102.0),
            (500160.0, 5400210.0, 102.0),
            (-60.0, 0.0, 0.0),
            2.0,
            3.0,
            "rejected",
            "rejected: misfit chi2 624 > 16.27",
        ),
        ControlRow(
            "scan_09.laz",
            (500250.0, 5400230.0, 103.0),
            None,
            None,
            2.0,
            3.0,
            "not used",
            "its scan is not in the anchor's cluster",
        ),
    )


def _cards(links: tuple[LinkRow, ...], png: bytes) -> tuple[LinkCard, ...]:
    """An inspector card per link: kept ones shown, the others on demand."""
    kept = ("confirmed", "not checked")
    return tuple(
        LinkCard(
            k.figure,
            f"{k.target} <- {k.source}",
            k.state,
            png,
            ("1 m: 12 of 20 match",),
            k.state in kept,
        )
        for k in links
    )


def _report(png: bytes) -> HtmlReport:
    """A report of a 12-scan street with hostile names, a figure and notes."""
    scans = _scans()
    links = _links(scans)
    return HtmlReport(
        title=f"Registration report: street {SCRIPT} & more",
        command=f"ndt-chain scans/*.laz --out street/ --jobs 4 # {SCRIPT}",
        created=datetime(2025, 3, 14, 9, 26, 53, tzinfo=UTC),
        version="ndt-cli 0.2.0",
        verdict=Verdict(
            ok=False,
            reason=f"link {HOSTILE} failed",
            remarks=(f"scan {LONG} left out (unposed): {SCRIPT}", "control station x rejected"),
        ),
        summary=(("scans", "12"), ("links", "14"), ("anchor", HOSTILE)),
        network=(("registrations tried", "15"), ("a-posteriori σ (unit weight)", "0.91")),
        controls=_controls(),
        control_note="Grid scale applied at the scanners: 0.99960000",
        scans=scans,
        links=links,
        figures=(Figure(png=png, caption=f"Top view of {HOSTILE}"),),
        cards=_cards(links, png),
        tried=(replace(links[0], state="not_planned", figure=""),),
        tried_note=(f"{LONG} (unposed): no link. Registrations tried for it: none",),
        config_yaml="grid:\n  cells: [20, 10, 5, 2, 1]\nname: '<&>'\n",
        notes=(f"Checked by <surveyor> & {SCRIPT}.",),
    )


@pytest.fixture(scope="module")
def page(png: bytes) -> str:
    """The rendered page."""
    return render_html(_report(png))


class _Balance(HTMLParser):
    """Checks that every element is closed in order; collects src/href attributes."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.stack: list[str] = []
        self.errors: list[str] = []
        self.urls: list[str] = []
        self.tags: set[str] = set()

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.add(tag)
        self.urls += [v or "" for k, v in attrs if k in ("src", "href", "srcset", "action")]
        if tag not in VOID:
            self.stack.append(tag)

    def handle_startendtag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.handle_starttag(tag, attrs)
        if tag not in VOID:
            self.stack.pop()

    def handle_endtag(self, tag: str) -> None:
        if tag in VOID:
            self.errors.append(f"end tag of void element </{tag}>")
        elif not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes {self.stack[-1:] or 'nothing'}")
        else:
            self.stack.pop()


def _parsed(page: str) -> _Balance:
    parser = _Balance()
    parser.feed(page)
    parser.close()
    return parser


def test_page_is_well_formed_html5(page: str) -> None:
    parser = _parsed(page)
    assert parser.errors == []
    assert parser.stack == []
    assert page.startswith("<!DOCTYPE html>\n")
    assert '<html lang="en">' in page
    assert '<meta charset="utf-8">' in page
    assert page.count("<title>") == 1
    assert {"table", "thead", "tbody", "figure", "img", "pre", "style"} <= parser.tags
    assert "script" not in parser.tags


def test_hostile_values_are_escaped(page: str) -> None:
    assert HOSTILE not in page
    assert SCRIPT not in page
    assert "<script" not in page.lower()
    assert "<surveyor>" not in page
    assert html.escape(HOSTILE, quote=True) in page
    assert html.escape(SCRIPT, quote=True) in page
    assert "name: &#x27;&lt;&amp;&gt;&#x27;" in page  # the YAML appendix


def test_every_scan_and_link_is_present(png: bytes, page: str) -> None:
    report = _report(png)
    tbody = page.split('id="scans"', 1)[1].split("</table>", 1)[0]
    assert tbody.count("<tr>") == len(report.scans) + 1  # + the column header row
    for scan in report.scans:
        assert html.escape(scan.name) in tbody
    links = page.split('id="links"', 1)[1].split("</table>", 1)[0]
    assert links.count("<tr>") == len(report.links) + 1
    for link in report.links:
        row = f'<td class="name" data-label="target">{html.escape(link.target)}</td>'
        row += f'<td class="name" data-label="source">{html.escape(link.source)}</td>'
        assert row + f'<td class="word" data-label="kind">{link.kind}</td>' in links


def test_figure_is_embedded_as_data_uri(png: bytes, page: str) -> None:
    uri = "data:image/png;base64," + base64.b64encode(png).decode("ascii")
    assert f'<img src="{uri}"' in page
    urls = _parsed(page).urls
    images = [u for u in urls if not u.startswith("#")]  # links within the page: figures' ids
    assert images and all(url.startswith("data:image/png;base64,") for url in images)
    ids = set(re.findall(r' id="([^"]+)"', page))
    assert {u[1:] for u in urls if u.startswith("#")} <= ids
    with pytest.raises(ValueError, match="not a PNG"):
        render_html(HtmlReport("t", "c", "now", "v", Verdict(True), figures=(Figure(b"GIF", "x"),)))


def test_no_network_reference(page: str) -> None:
    lowered = page.lower()
    for scheme in ("http://", "https://", "//fonts", "@import", "url("):
        assert scheme not in lowered
    assert "default-src 'none'" in page  # the CSP forbids fetches in any browser


def test_status_is_coloured_and_written(page: str) -> None:
    assert '<span class="st st-ok">ok</span>' in page
    assert '<span class="st st-ok">used</span>' in page
    assert '<span class="st st-warn">suspect</span>' in page
    assert '<span class="st st-warn">degenerate</span>' in page
    assert '<span class="st st-bad">failed</span>' in page
    assert '<span class="st st-bad">rejected</span>' in page
    assert '<span class="st st-bad">unposed</span>' in page
    assert '<span class="st st-bad">not converged</span>' in page
    assert '<span class="st st-info">not checked</span>' in page  # never green
    assert '<div class="verdict bad" id="verdict"><p><strong>Result: NOT OK</strong>' in page
    assert status_class("Not-Converged") == "bad"
    assert status_class("something else") == "none"


def test_numbers_units_and_missing_values(page: str) -> None:
    for header in ("x (m)", "yaw (deg)", "σx (cm)", "σyaw (deg)", "overlap (%)", "ICP RMS (cm)"):
        assert f'<th scope="col">{header}</th>' in page
    assert '<td class="num" data-label="x (m)">14.877</td>' in page  # x of scan 1: 15 - 0.123 m
    assert '<td class="num" data-label="overlap (%)">80.0</td>' in page  # 0.8 shown in %
    assert '<td class="empty" data-label="σy (cm)">\u2013</td>' in page  # NaN
    assert '<td class="num" data-label="up">free</td>' in page  # 4 m: not pinned at all
    assert "nan" not in page.split("<tbody>", 1)[1].lower().split("</tbody>", 1)[0]
    assert "2025-03-14 09:26:53+00:00" in page


def test_empty_report_renders() -> None:
    page = render_html(HtmlReport("Empty", "ndt-chain", "today", "ndt-cli", Verdict(True)))
    assert _parsed(page).errors == []
    assert "Result: OK" in page and "(not recorded)" in page and "none</td>" in page


def test_every_status_a_run_gives_is_coloured_and_no_other_word_is_listed() -> None:
    from ndt_cli.ndt.result import Status
    from ndt_cli.pipeline.result import Dropped
    from ndt_cli.pipeline.verify import EdgeState, NodeStatus
    from ndt_cli.report.html_chain import STATE_WORDS

    words = {w.replace(" ", "_") for w in STATE_WORDS.values()} | {d.value for d in Dropped}
    produced = {s.value for s in (*Status, *NodeStatus, *EdgeState)} | {"anchor"} | words
    grey = {EdgeState.UNUSED.value, "not_used", *(d.value for d in Dropped)}
    assert set(STATUS_CLASSES) == produced - grey
    assert all(status_class(word) == "none" for word in grey)
    assert status_class(STATE_WORDS[EdgeState.USED]) == "info"  # not checked: never green
    assert status_class(Status.NO_OVERLAP) == "bad" and status_class(NodeStatus.SUSPECT) == "warn"


def test_a_report_shows_the_command_it_is_given_and_none_without_one(monkeypatch) -> None:
    """The command line comes from the caller (the CLI); a library call shows none, never the
    command line of the process it runs in."""
    import sys

    from ndt_cli.cli.common import command_line
    from ndt_cli.report.html_report import render

    monkeypatch.setattr(sys, "argv", ["/usr/local/bin/ndt-chain", "scan 1.laz", "-o", "out"])
    assert command_line() == "ndt-chain 'scan 1.laz' -o out"
    given = render(command_line(), verdict=Verdict(True))
    assert '<th scope="row">Command</th><td><code>ndt-chain &#x27;scan 1.laz&#x27; -o out' in given
    library = render("", verdict=Verdict(True))
    assert ">Command<" not in library and "ndt-chain" not in library
    assert _parsed(library).errors == []


# ---------------------------------------------------------------- the page in a real browser


def _browser_or_skip() -> Any:
    """Playwright's sync API; skip (fail when CI is "true") without it or without Chromium."""
    missing = ""
    if shutil.which("chromium") is None or not Path(CHROMIUM).exists():
        missing = f"Chromium not found at {CHROMIUM} (Debian: apt-get install chromium)"
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        missing = missing or "the Python package playwright is not installed"
    if missing:
        if os.environ.get("CI") == "true":
            pytest.fail(missing)
        pytest.skip(missing)
    return sync_playwright


LAUNCH_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--no-first-run",
    "--disable-sync",
]


@pytest.mark.parametrize("ci", ["true", ""])
def test_missing_browser_skips_or_fails_on_ci(monkeypatch: pytest.MonkeyPatch, ci: str) -> None:
    monkeypatch.setenv("CI", ci)
    monkeypatch.setattr(shutil, "which", lambda name: None)
    expected = pytest.fail.Exception if ci else pytest.skip.Exception
    with pytest.raises(expected, match="Chromium not found"):
        _browser_or_skip()


def _crop(shot: Any, box: dict[str, float]) -> Any:
    """The part of the screenshot inside an element's bounding box (page coordinates)."""
    left, top = math.ceil(box["x"]), math.ceil(box["y"])
    right, bottom = int(box["x"] + box["width"]), int(box["y"] + box["height"])
    return shot.crop((left, top, right, bottom))


def _check_pixels(shot: Any, boxes: dict[str, dict[str, float]]) -> None:
    """The picture, the table text and the status colours are really drawn."""
    import numpy as np

    img = _crop(shot, boxes["img"])
    assert img.width > 100 and img.height > 50
    colours = img.getcolors(maxcolors=1 << 20)
    assert colours is not None and len(colours) > 50, "the embedded picture is not drawn"
    table = _crop(shot, boxes["table"]).convert("L")
    dark = sum(table.histogram()[:100])
    assert dark > 2000, f"the scan table shows no text ({dark} dark pixels)"
    bad = np.asarray(_crop(shot, boxes["bad"])).astype(int)
    ok = np.asarray(_crop(shot, boxes["ok"])).astype(int)
    red = (bad[..., 0] > 150) & (bad[..., 1] < 90)
    green = (ok[..., 1] > 90) & (ok[..., 0] < 80)
    assert red.any() and green.any(), "status badges are not coloured"


def _boxes(pg: Any) -> dict[str, dict[str, float]]:
    """Bounding boxes of the figure, the scan table and two status badges."""
    handles = {
        "img": pg.locator("#figures-section figure img").first,
        "table": pg.locator("table#scans"),
        "bad": pg.locator("span.st-bad", has_text="failed").first,
        "ok": pg.locator("#links span.st-ok", has_text="ok").first,
    }
    boxes = {}
    for name, handle in handles.items():
        box = handle.bounding_box()
        assert box is not None and box["width"] > 0 and box["height"] > 0, name
        boxes[name] = dict(box)
    return boxes


def _print_fits(pg: Any) -> None:
    """In print media at the width of A4 less its margins, no table is wider than the page."""
    pg.set_viewport_size({"width": 704, "height": 1000})  # 186 mm at 96 dpi
    pg.emulate_media(media="print")
    widths = pg.evaluate(
        "() => [document.documentElement.scrollWidth, window.innerWidth,"
        " ...[...document.querySelectorAll('table, pre, figure')]"
        ".map(t => Math.ceil(t.getBoundingClientRect().right))]"
    )
    page_width = widths[1]
    assert max(widths[0], *widths[2:]) <= page_width, f"print overflow: {widths}"
    assert pg.pdf(format="A4").startswith(b"%PDF")


def _images_loaded(pg: Any) -> int:
    """How many images the page holds, all of them decoded (those on demand too)."""
    pg.evaluate("() => document.querySelectorAll('details').forEach(d => { d.open = true; })")
    pg.wait_for_load_state("load")
    loaded = pg.eval_on_selector_all(
        "img", "els => els.map(i => i.complete && i.naturalWidth > 0 && i.naturalHeight > 0)"
    )
    assert loaded and all(loaded), loaded
    return len(loaded)


STACKED = """() => {
  const rows = [...document.querySelectorAll('table.data tbody td')];
  const heads = [...document.querySelectorAll('table.data thead')];
  return {
    hidden: heads.every(h => getComputedStyle(h).display === 'none'),
    labelled: rows.every(td => getComputedStyle(td, '::before').content
      === JSON.stringify(td.dataset.label)),
    cells: rows.length,
  };
}"""


def _fits_the_screen(pg: Any, width: int) -> None:
    """At ``width`` px nothing scrolls sideways; on a phone the tables are stacked, every cell
    preceded by its column's name."""
    pg.set_viewport_size({"width": width, "height": 900})
    widths = pg.evaluate(
        "() => [document.documentElement.scrollWidth, window.innerWidth,"
        " ...[...document.querySelectorAll('table, pre, figure, img, .verdict')]"
        ".map(t => Math.ceil(t.getBoundingClientRect().right))]"
    )
    assert max(widths[0], *widths[2:]) <= widths[1], f"{width} px: sideways scroll {widths}"
    stacked = pg.evaluate(STACKED)
    assert stacked["cells"] > 100
    assert stacked["hidden"] == stacked["labelled"] == (width < 720), (width, stacked)


@pytest.mark.slow
def test_page_in_real_browser(tmp_path: Path, png: bytes) -> None:
    from PIL import Image

    sync_playwright = _browser_or_skip()
    path = tmp_path / "report.html"
    path.write_text(render_html(_report(png)), encoding="utf-8")
    url = path.as_uri()
    errors: list[str] = []
    requests: list[str] = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=LAUNCH_ARGS)
        try:
            context = browser.new_context(viewport={"width": 1280, "height": 900})
            pg = context.new_page()
            pg.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            pg.on("pageerror", lambda e: errors.append(str(e)))
            context.on("request", lambda r: requests.append(r.url))
            response = pg.goto(url, wait_until="load")
            assert response is None or response.ok
            assert pg.title().startswith("Registration report")
            assert _images_loaded(pg) == 1 + len(_report(png).cards)
            boxes = _boxes(pg)
            shot = Image.open(io.BytesIO(pg.screenshot(full_page=True))).convert("RGB")
            for width in (1024, 400):
                _fits_the_screen(pg, width)
            _print_fits(pg)
        finally:
            browser.close()
    assert requests and requests[0] == url
    assert all(r == url or r.startswith("data:") for r in requests), requests
    assert errors == []
    _check_pixels(shot, boxes)


def test_verdict_names_what_it_rests_on_and_the_control_table_shows_every_station(
    png: bytes, page: str
) -> None:
    verdict = page.split('id="verdict"', 1)[1].split("</div>", 1)[0]
    assert f"<li>scan {html.escape(LONG)} left out (unposed): {html.escape(SCRIPT)}</li>" in verdict
    assert "<li>control station x rejected</li>" in verdict
    table = page.split('id="controls"', 1)[1].split("</table>", 1)[0]
    assert table.count("<tr>") == len(_controls()) + 1
    for station in _controls():
        assert f'data-label="station">{html.escape(station.station)}</td>' in table
    assert '<td class="num" data-label="ΔE">-60.0</td>' in table  # adjusted - given, cm
    assert '<span class="st st-bad">rejected</span>' in table
    assert '<td class="num" data-label="E">500160.600</td>' in table  # never 5.0016e+05
    assert "0.99960000" in page.split('id="control-note"', 1)[1].split("</p>", 1)[0]


def test_every_link_has_a_figure_kept_ones_shown_the_others_on_demand(page: str) -> None:
    cards = re.findall(r'<figure class="link" id="(link-\d+)">(.*?)</figure>', page, re.S)
    links = _links(_scans())
    assert [c[0] for c in cards if "<details>" not in c[1]] == [
        k.figure for k in links if k.state in ("confirmed", "not checked")
    ]
    for anchor, body in cards:
        assert body.count("<img ") == 1, anchor
        if "<details>" in body:  # on demand: the picture inside the closed details
            assert body.index("<details>") < body.index("<img ")
    for link in links:  # every row of the link table points at its figure
        assert f'<a href="#{link.figure}">view</a>' in page
    tried = page.split('id="tried"', 1)[1].split("</table>", 1)[0]
    assert '<span class="st st-none">not planned</span>' in tried
