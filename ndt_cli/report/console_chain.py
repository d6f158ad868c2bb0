"""A campaign's summary on the terminal: its links, the registrations tried and left out, the
scans that are not ok, the control stations, the world frame and the verdict with what it
rests on, each table fitted to the terminal (:mod:`ndt_cli.report.console_fit`): names and
numbers whole, statuses coloured, as the report words them."""

from __future__ import annotations

from typing import Any

from ndt_cli.pipeline.result import ChainResult
from ndt_cli.pipeline.verify import EdgeState
from ndt_cli.report.console_fit import Col, print_fitted, styled
from ndt_cli.report.html_chain import STATE_WORDS
from ndt_cli.report.reasons import network_note
from ndt_cli.report.tables import pair_row
from ndt_cli.report.verdict import judge
from ndt_cli.report.world import world_line, world_summary

_OPTIONAL = ("pose", "score", "kind", "overlap")  # dropped in this order when too wide


def _pair(result: ChainResult, link: Any) -> tuple[str, str]:
    return result.names[link.target], result.names[link.source]


def _link_column(pairs: list[tuple[str, str]], full: bool) -> Col:
    """``target <- source``: on one line, or wrapped after the arrow (as wide as the longest
    name plus the arrow)."""
    cells = [f"{t} <- {s}" for t, s in pairs]
    width = None if full else max((max(len(t) + 3, len(s)) for t, s in pairs), default=4)
    return Col("target <- source", cells, width=width)


def _link_layouts(
    result: ChainResult, links: list, fits: list, states: list[str], why: list[str]
) -> list:
    """The layouts of a table of links (``fits``: what the network made of each, None for a
    registration left out), richest first; a link no cycle checks shows no residual."""
    rows = [pair_row(k, result.names) for k in links]
    pairs = [_pair(result, k) for k in links]
    residual = []
    for fit in fits:
        shown = fit is not None and fit.residual and fit.state is not EdgeState.USED
        residual.append(f"{100 * fit.residual.translation_m:.2f} cm" if shown else "")
    optional = {
        "pose": [
            Col("tx (m)", [r["tx"] for r in rows], justify="right"),
            Col("ty (m)", [r["ty"] for r in rows], justify="right"),
            Col("yaw (deg)", [r["yaw_deg"] for r in rows], justify="right"),
        ],
        "score": [Col("score/pt", [r["score_per_point"] for r in rows], justify="right")],
        "kind": [Col("kind", [k.kind.value for k in links])],
        "overlap": [Col("overlap", [_percent(r["overlap"]) for r in rows], justify="right")],
    }
    layouts = []
    for full in (True, False):
        for drop in range(len(_OPTIONAL) + 1):
            if full and drop == len(_OPTIONAL):
                continue
            keep = _OPTIONAL[drop:]
            cols = [Col("#", [str(k.index) for k in links], justify="right")]
            cols.append(_link_column(pairs, full))
            cols += optional["kind"] if "kind" in keep else []
            cols += optional["pose"] if "pose" in keep else []
            cols += optional["score"] if "score" in keep else []
            cols += optional["overlap"] if "overlap" in keep else []
            cols.append(Col("registration", [styled(k.status.value) for k in links]))
            cols.append(Col("network", [styled(s) for s in states]))
            if any(residual):
                cols.append(Col("residual", residual, justify="right"))
            cols.append(Col("why", why, text=True))
            layouts.append(cols)
    return layouts


def _percent(fraction: str) -> str:
    return "" if not fraction else f"{100 * float(fraction):.0f} %"


def _links(result: ChainResult, console: Any) -> None:
    links = list(result.links)
    states, why = [], []
    for link, fit in zip(links, result.solution.links, strict=True):
        states.append(STATE_WORDS[fit.state])
        why.append("; ".join(w for w in (link.reason, network_note(link, fit)) if w))
    fits = list(result.solution.links)
    layouts = _link_layouts(result, links, fits, states, why)
    print_fitted(console, layouts, "links of the network", 2)
    if result.tried:
        tried = [t.link for t in result.tried]
        words = [t.why.value.replace("_", " ") for t in result.tried]
        reasons = [t.link.reason for t in result.tried]
        layouts = _link_layouts(result, tried, [None] * len(tried), words, reasons)
        print_fitted(console, layouts, "registrations tried and left out of the network", 2)


def _scans(result: ChainResult, console: Any) -> None:
    bad = [(k, s) for k, s in enumerate(result.solution.scans) if not s.anchored]
    if not bad:
        return
    names = [result.names[k] for k, _ in bad]
    status = [styled(s.status.value) for _, s in bad]
    cluster = ["" if s.cluster is None else str(s.cluster) for _, s in bad]
    reason = [s.reason or "not tied to the anchor: its cluster's own frame" for _, s in bad]
    cols = [Col("scan", names), Col("status", status), Col("cluster", cluster)]
    print_fitted(console, [[*cols, Col("reason", reason, text=True)]], "scans not ok")


def _controls(result: ChainResult, console: Any) -> None:
    rows = world_summary(result)["controls"]
    if not rows:
        return
    given = [[f"{r['given'][k]:.3f}" for r in rows] for k in range(3)]
    res = [["" if r["residual_cm"] is None else f"{r['residual_cm'][k]:+.1f}" for r in rows]
           for k in range(3)]  # fmt: skip
    used = [styled("used" if r["used"] else "rejected") for r in rows]
    head = [Col("station", [r["scan"] for r in rows])]
    tail = [
        *(Col(f"Δ{a} (cm)", res[k], justify="right") for k, a in enumerate("ENh")),
        Col("used", used),
        Col("why", [r["reason"] for r in rows], text=True),
    ]
    full = [*head, *(Col(f"{a} (m)", given[k], justify="right") for k, a in enumerate("ENh"))]
    print_fitted(console, [[*full, *tail], [*head, *tail]], "control stations")


def print_chain_summary(result: ChainResult, console: Any) -> None:
    """Every table of a campaign's summary, then the world frame and the verdict."""
    from rich.text import Text

    _links(result, console)
    _scans(result, console)
    _controls(result, console)
    console.print(Text(world_line(result)), soft_wrap=False, overflow="fold")
    verdict = judge(result)
    style = {"ok": "bold green", "remarks": "bold yellow", "bad": "bold red"}[verdict.level]
    word = {"ok": "OK", "remarks": "OK, with remarks", "bad": "NOT OK"}[verdict.level]
    adjusted = " (adjusted)" if result.solution.adjusted else ""
    line = Text(f"{word}: ", style=style) + Text(verdict.headline + adjusted)
    console.print(line, soft_wrap=False, overflow="fold")
    if verdict.remarks:
        from rich.table import Table

        remarks = Table.grid(padding=(0, 1))
        remarks.add_column(width=1)
        remarks.add_column(overflow="fold")
        for remark in verdict.remarks:
            remarks.add_row("-", Text(remark))
        console.print(remarks)
