"""Why a scan is not ok, in the scans' names.

The network states its reasons with indices (``posed only through unused link 2 (T_0_2)``,
``only rejected links: 1, 4``, ``link 3-5 failed``): the edge index counts only the links the
adjustment used. Every output shows them with the names of the scans instead
(``posed only through unused link scan_00.laz <- scan_02.laz``). A scan with "no link" in the
network but registrations tried for it says how many and how they came out.
"""

from __future__ import annotations

import re
from collections import Counter
from dataclasses import replace

from ndt_cli.pipeline.link_use import usable
from ndt_cli.pipeline.links import Link
from ndt_cli.pipeline.result import ChainResult
from ndt_cli.pipeline.solution import LinkFit
from ndt_cli.pipeline.verify import EdgeState

_VIA = re.compile(r"link (\d+) \(T_(\d+)_(\d+)\)")
_REJECTED = re.compile(r"(only rejected links: )([\d, ]+)")
_PAIR = re.compile(r"\blink (\d+)-(\d+)\b")


def network_note(link: Link, fit: LinkFit | None) -> str:
    """What the network says of a link, where the link's own words do not explain its state:
    rejected, left unused though its gate passed it (a bridge nothing checks), or used though
    its gate did not pass it (vouched for by the walk, a weak link joining groups); '' else."""
    if fit is None or not fit.reason:
        return ""
    used = fit.state in (EdgeState.USED, EdgeState.CONFIRMED)
    return f"network: {fit.reason}" if fit.state is EdgeState.REJECTED or used != link.ok else ""


def named_reason(reason: str, names: tuple[str, ...], used: list[tuple[int, int]]) -> str:
    """``reason`` with its links named ``target <- source`` (``used``: the (target, source)
    of the links the adjustment used, in its order)."""

    def link(t: int, s: int) -> str:
        return f"{names[t]} <- {names[s]}"

    def rejected(m: re.Match) -> str:
        edges = [int(k) for k in m[2].replace(" ", "").split(",") if k]
        return m[1] + ", ".join(link(*used[k]) for k in edges if k < len(used))

    text = _VIA.sub(lambda m: f"link {link(int(m[2]), int(m[3]))}", reason)
    text = _REJECTED.sub(rejected, text)
    return _PAIR.sub(lambda m: f"link {link(int(m[1]), int(m[2]))}", text)


def tried_for(result: ChainResult, scan: int, reason: str) -> str:
    """``reason`` of a scan with no link in the network, with the registrations tried for it
    and how they came out (``reason`` as it is for any other)."""
    if reason != "no link":
        return reason
    every = [*result.links, *(t.link for t in result.tried)]
    mine = [k for k in every if scan in (k.target, k.source)]
    if not mine:
        return reason
    counts = ", ".join(f"{n} {s}" for s, n in Counter(k.status.value for k in mine).items())
    return (
        f"no link kept: {len(mine)} registration(s) tried for it ({counts}); pairs.csv and "
        "the report list them with their reasons"
    )


def with_named_reasons(result: ChainResult) -> ChainResult:
    """``result`` with every scan's reason naming its links by the scans' names."""
    used = [(k.target, k.source) for k in result.links if usable(k)]
    sol = result.solution
    scans = tuple(
        replace(s, reason=tried_for(result, k, named_reason(s.reason, result.names, used)))
        for k, s in enumerate(sol.scans)
    )
    return replace(result, solution=replace(sol, scans=scans))
