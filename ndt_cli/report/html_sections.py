"""The report's sections of rows: control stations, scans, links, the link inspector and the
registrations tried; each row a frozen dataclass the caller fills (:mod:`ndt_cli.report.html`
puts the sections on the page)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from ndt_cli.report.html_parts import (
    DASH,
    Column,
    badge,
    data_table,
    esc,
    num,
    numeric,
    text,
)


@dataclass(frozen=True)
class ScanRow:
    """One scan: its pose in the world frame and its standard deviations (1 sigma).

    ``status`` is free text such as ``ok``, ``anchor``, ``unposed`` or ``unreadable``; any
    number may be None (not known). ``reason`` explains a status that is not ok.
    """

    name: str
    status: str = ""
    x_m: float | None = None
    y_m: float | None = None
    z_m: float | None = None
    yaw_deg: float | None = None
    sd_x_cm: float | None = None
    sd_y_cm: float | None = None
    sd_z_cm: float | None = None
    sd_yaw_deg: float | None = None
    reason: str = ""


@dataclass(frozen=True)
class LinkRow:
    """One link (or registration tried): its registration, its state and its residual after
    the adjustment, its strength and where its inspector figure is.

    ``kind``: adjacent, past, found, user, pair; ``status``: the registration's (ok, suspect,
    degenerate, not_converged, no_overlap, failed); ``state``: the link in the network as the
    report words it (confirmed, not checked, rejected, not used; a registration left out: not
    planned, other way kept). ``overlap`` is a fraction (0-1, shown in %); a link no cycle
    checks has no residual. ``strength_mm``: 1-sigma along, across, up (mm; None: no
    transform); ``figure``: the id of its inspector figure ('' : none); ``network``: the
    network's note (also among ``warnings``), as :func:`~ndt_cli.report.reasons.network_note`.
    """

    kind: str
    target: str
    source: str
    status: str = ""
    state: str = ""
    score_per_point: float | None = None
    overlap: float | None = None
    ambiguity: float | None = None
    icp_rms_cm: float | None = None
    residual_deg: float | None = None
    residual_cm: float | None = None
    warnings: tuple[str, ...] = ()
    strength_mm: tuple[float, float, float] | None = None
    figure: str = ""
    network: str = ""  # what the network says of it, where its own words do not explain it


@dataclass(frozen=True)
class ControlRow:
    """A control station: its scan, given and adjusted coordinates (m; None: not adjusted),
    adjusted minus given (cm, E N h), its given standard deviations (cm), its ``state`` (used,
    rejected, not used) and why."""

    station: str
    given: tuple[float, float, float]
    adjusted: tuple[float, float, float] | None
    residual_cm: tuple[float, float, float] | None
    sigma_xy_cm: float
    sigma_z_cm: float
    state: str
    reason: str = ""


@dataclass(frozen=True)
class LinkCard:
    """A link inspector figure: its ``anchor`` id, its ``title`` (``target <- source``), state,
    picture (PNG; None: nothing to show), caption lines, and whether it is ``kept`` (shown)
    or left out (shown on demand)."""

    anchor: str
    title: str
    state: str
    png: bytes | None
    lines: tuple[str, ...]
    kept: bool


def _strength(k: int) -> Callable[[LinkRow], str]:
    def get(row: LinkRow) -> str:
        if row.strength_mm is None:
            return ""
        v = row.strength_mm[k]
        return "free" if v > 1000 else f"{v:.0f}"

    return get


def _figure_link(row: LinkRow) -> str:
    return f'<a href="#{esc(row.figure)}">view</a>' if row.figure else ""


_SCAN_GROUPS = (("Scan", 2), ("Pose in the world frame", 4), ("Standard deviation (1σ)", 4))
_SCAN_GROUPS += (("", 1),)
_SCAN_COLUMNS = (
    Column("scan", text("name"), "name"),
    Column("status", text("status"), "status"),
    Column("x (m)", numeric("x_m", 3), "num"),
    Column("y (m)", numeric("y_m", 3), "num"),
    Column("z (m)", numeric("z_m", 3), "num"),
    Column("yaw (deg)", numeric("yaw_deg", 4), "num"),
    Column("σx (cm)", numeric("sd_x_cm", 2), "num"),
    Column("σy (cm)", numeric("sd_y_cm", 2), "num"),
    Column("σz (cm)", numeric("sd_z_cm", 2), "num"),
    Column("σyaw (deg)", numeric("sd_yaw_deg", 4), "num"),
    Column("reason", text("reason")),
)
_LINK_HEAD = (
    Column("target", text("target"), "name"),
    Column("source", text("source"), "name"),
    Column("kind", text("kind"), "word"),
    Column("status", text("status"), "status"),
    Column("overlap (%)", numeric("overlap", 1, 100.0), "num"),
    Column("ICP RMS (cm)", numeric("icp_rms_cm", 2), "num"),
)
_LINK_GROUPS = (("Link", 3), ("Registration", 3), ("Network adjustment", 3))
_LINK_GROUPS += (("Strength σ (mm)", 3), ("", 2))
_LINK_COLUMNS = (
    *_LINK_HEAD,
    Column("state", text("state"), "status"),
    Column("residual (cm)", numeric("residual_cm", 2), "num"),
    Column("residual (deg)", numeric("residual_deg", 4), "num"),
    Column("along", _strength(0), "num"),
    Column("across", _strength(1), "num"),
    Column("up", _strength(2), "num"),
    Column("slices", _figure_link, "html"),
    Column("notes", lambda link: "\n".join(link.warnings)),
)
_TRIED_COLUMNS = (
    *_LINK_HEAD,
    Column("left out", text("state"), "status"),
    Column("slices", _figure_link, "html"),
    Column("notes", lambda link: "\n".join(link.warnings)),
)

_LEGEND = (
    '<p class="legend">Status colours: <span class="st st-ok">green</span> ok, confirmed; '
    '<span class="st st-info">dashed blue</span> not checked (no cycle checks it: kept on its '
    "own quality gate's word or, where the gate doubted it, on the network's, its reason given); "
    '<span class="st st-warn">amber</span> suspect, degenerate; '
    '<span class="st st-bad">red</span> failed, rejected, unposed. '
    f"{DASH} : no value.</p>"
)


def tables(
    scans: tuple[ScanRow, ...], links: tuple[LinkRow, ...], n_scans: int, n_links: int
) -> str:
    """The sections of the scan table and the link table (numbered ``n_scans``, ``n_links``)."""
    scan_table = data_table(scans, _SCAN_COLUMNS, _SCAN_GROUPS, "scans")
    link_table = data_table(links, _LINK_COLUMNS, _LINK_GROUPS, "links")
    return (
        f'<section id="scans-section"><h2>{n_scans}. Scans ({len(scans)})</h2>\n{scan_table}\n'
        f"{_LEGEND}</section>\n"
        f'<section id="links-section"><h2>{n_links}. Links ({len(links)})</h2>\n{link_table}\n'
        '<p class="legend">Registration: the pairwise result; network adjustment: the link\'s '
        "state and its residual after the adjustment (a link no cycle checks has none); "
        "strength: how well the link's geometry pins the source scanner down along the line "
        "between the scanners, across it and up (1σ, mm; free: not at all); slices: the link "
        "inspector's figure.</p></section>"
    )


_CONTROL_GROUPS = (("", 1), ("Given (m)", 3), ("Adjusted (m)", 3), ("Adjusted − given (cm)", 3))
_CONTROL_GROUPS += (("Given σ (cm)", 2), ("", 2))


def _xyz(attr: str, k: int, digits: int) -> Callable[[ControlRow], str]:
    def get(row: ControlRow) -> str:
        v = getattr(row, attr)
        return "" if v is None else num(v[k], digits)

    return get


_CONTROL_COLUMNS = (
    Column("station", text("station"), "name"),
    *(Column(a, _xyz("given", k, 3), "num") for k, a in enumerate(("E", "N", "h"))),
    *(Column(a + " ", _xyz("adjusted", k, 3), "num") for k, a in enumerate(("E", "N", "h"))),
    *(Column(f"Δ{a}", _xyz("residual_cm", k, 1), "num") for k, a in enumerate(("E", "N", "h"))),
    Column("σ horizontal", numeric("sigma_xy_cm", 1), "num"),
    Column("σ height", numeric("sigma_z_cm", 1), "num"),
    Column("used", text("state"), "status"),
    Column("why", text("reason")),
)


def control_section(rows: tuple[ControlRow, ...], note: str, number: int) -> str:
    """The control stations' table and what it rests on."""
    table = data_table(rows, _CONTROL_COLUMNS, _CONTROL_GROUPS, "controls")
    return (
        f'<section id="control-section"><h2>{number}. Control ({len(rows)} stations)</h2>\n'
        f'{table}\n<p class="note" id="control-note">{esc(note)}</p></section>'
    )


def _card(card: LinkCard, img: Callable[[bytes, str], str]) -> str:
    picture = img(card.png, f"slices of {card.title}") if card.png else ""
    lines = "<br>".join(esc(line) for line in card.lines)
    caption = f"<figcaption><b>{esc(card.title)} {badge(card.state)}</b>{lines}</figcaption>"
    if card.kept:
        return f'<figure class="link" id="{esc(card.anchor)}">{picture}{caption}</figure>'
    return (
        f'<figure class="link" id="{esc(card.anchor)}">{caption}<details>'
        f"<summary>show the slices</summary>{picture}</details></figure>"
    )


_INSPECTOR_LEGEND = (
    '<p class="legend">Each figure shows a link\'s two scans cut at two heights above the '
    "ground, in the target scan's frame, zoomed on where they overlap: "
    '<span class="key" style="background:#1f77b4"></span> target, '
    '<span class="key" style="background:#ff7f0e"></span> source. A right link draws one '
    "outline where the scans see the same walls, poles and cars; a wrong one draws two, "
    "offset or turned. The residuals are the distances of the source's points from the "
    "target's outline nearby (median and upper quartile): a median under 1 cm on a right "
    "link.</p>"
)


def inspector_section(
    cards: tuple[LinkCard, ...], number: int, img: Callable[[bytes, str], str]
) -> str:
    """The link inspector: a figure per kept link, and on demand for the others."""
    kept = "\n".join(_card(c, img) for c in cards if c.kept)
    other = "\n".join(_card(c, img) for c in cards if not c.kept)
    rest = f'<h3>Links not kept</h3>\n<div class="cards">{other}</div>' if other else ""
    return (
        f'<section id="inspector-section"><h2>{number}. Link inspector</h2>\n{_INSPECTOR_LEGEND}'
        f'\n<div class="cards">{kept}</div>\n{rest}</section>'
    )


def tried_section(rows: tuple[LinkRow, ...], notes: tuple[str, ...], number: int) -> str:
    """The registrations tried and left out, and why scans are not ok."""
    why = "".join(f"<li>{esc(n)}</li>" for n in notes)
    scans = f'<h3>Scans left out</h3>\n<ul id="left-out">{why}</ul>' if why else ""
    table = data_table(rows, _TRIED_COLUMNS, (), "tried")
    return (
        f'<section id="tried-section"><h2>{number}. Registrations tried</h2>\n{scans}\n'
        '<p class="note">Every registration the run tried that is not a link of the network: '
        "registered while placing a scan (its pair is not among the nearest scans the network "
        "was planned from), or the same pair the other way round (the better one is kept)."
        f"</p>\n{table}</section>"
    )
