"""The verdict of a campaign, as the report's first lines say it: one word for the whole (OK,
OK with remarks, NOT OK) and, by name, everything a surveyor must know before signing: the
scans left out or not tied to the anchor, the control stations rejected, the links rejected,
the links no cycle checks, the registrations tried and left out.

NOT OK when a scan is not ok in the anchor's cluster, or control was given and could not
place the campaign (not georeferenced; the run exits 1); OK with remarks when
every scan is, but a station or a link was rejected or a kept link is not checked by any
cycle (the run exits 0: the remarks say what the result rests on).
"""

from __future__ import annotations

from dataclasses import dataclass

from ndt_cli.pipeline.result import ChainResult
from ndt_cli.pipeline.verify import EdgeState, NodeStatus
from ndt_cli.report.world import world_summary

MAX_NAMED = 12  # links named in one remark; more are counted


@dataclass(frozen=True)
class Judgement:
    """``level``: ``ok``, ``remarks`` (ok, with things to know) or ``bad``; ``headline``: one
    line after the level's word; ``remarks``: one line per thing to know, naming it."""

    level: str
    headline: str
    remarks: tuple[str, ...]


def _named(links: list[str]) -> str:
    shown = ", ".join(links[:MAX_NAMED])
    return shown + (f" and {len(links) - MAX_NAMED} more" if len(links) > MAX_NAMED else "")


def _scan_remarks(result: ChainResult) -> list[str]:
    out = []
    for name, s in zip(result.names, result.solution.scans, strict=True):
        if s.status is not NodeStatus.OK:
            out.append(f"scan {name} left out ({s.status.value}): {s.reason}")
        elif s.cluster:
            out.append(
                f"scan {name} ok in cluster {s.cluster} only: no kept link ties it to the anchor"
            )
    return out


def _control_remarks(result: ChainResult) -> list[str]:
    out = []
    for r in world_summary(result)["controls"]:
        if not r["used"]:
            res = r["residual_cm"]
            misfit = (
                ""
                if res is None
                else " (adjusted - given: {:+.1f} {:+.1f} {:+.1f} cm)".format(*res)
            )
            out.append(f"control station {r['scan']} not used: {r['reason']}{misfit}")
    return out


def _link_remarks(result: ChainResult) -> list[str]:
    """The links rejected, and those used with no cycle to check them: on their gate's word,
    or on the network's though their gate doubted them (vouched for by the walk)."""
    rejected, by_gate, doubted = [], [], []
    for link, fit in zip(result.links, result.solution.links, strict=True):
        name = f"{result.names[link.target]} <- {result.names[link.source]}"
        if fit.state is EdgeState.REJECTED:
            rejected.append(name)
        elif fit.state is EdgeState.USED:
            (by_gate if link.ok else doubted).append(name)
    out = []
    if rejected:
        out.append(f"{len(rejected)} link(s) rejected by the adjustment: {_named(rejected)}")
    if by_gate:
        out.append(
            f"{len(by_gate)} link(s) not checked by any cycle (kept on their own quality gate's "
            f"word): {_named(by_gate)}"
        )
    if doubted:
        out.append(
            f"{len(doubted)} link(s) not checked by any cycle and doubted by their gate, kept on "
            f"the network's word (its reason in the link table): {_named(doubted)}"
        )
    return out


def judge(result: ChainResult) -> Judgement:
    """The verdict of ``result`` (see the module docstring)."""
    scans = _scan_remarks(result)
    problem = result.not_georeferenced
    world = [f"not georeferenced: {problem}"] if problem else []
    concerns = (*world, *scans, *_control_remarks(result), *_link_remarks(result))
    tried = len(result.tried)
    remarks = concerns + (
        (f"{tried} registration(s) tried and left out of the network: see Registrations tried",)
        if tried
        else ()
    )
    n, bad = len(result.names), sum(not s.anchored for s in result.solution.scans)
    if not result.ok and not bad:
        return Judgement("bad", f"NOT GEOREFERENCED; all {n} scans ok", remarks)
    if not result.ok:
        headline = f"{bad} of {n} scans not ok in the anchor's frame"
        return Judgement("bad", ("NOT GEOREFERENCED; " if problem else "") + headline, remarks)
    if concerns:
        return Judgement("remarks", f"all {n} scans ok", remarks)
    return Judgement("ok", f"all {n} scans ok, every link checked by a cycle", remarks)
