"""The numbers a surveyor signs a network by: how many registrations were tried, registered,
kept, checked; the residuals of the checked links; the adjustment's a-posteriori standard
deviation; and each link's strength.

A link's **strength** (as Cyclone REGISTER 360 shows it per link) is how well its geometry pins
the source scanner's position down in the target's frame, per direction: *along* the line
between the two scanners (on a street, along the street), *across* it (horizontal) and *up*.
It is the 1-sigma of that position from the link's covariance (the inverse of its information,
the ICP normal matrix or the NDT Hessian, as the adjustment weighs it:
:func:`ndt_cli.pipeline.link_use.link_covariance`): a few millimetres for a strong link, metres
along a corridor whose walls give nothing along it.

The **a-posteriori standard deviation of unit weight** is sqrt(sum of the kept links' chi-square
/ redundancy), the redundancy 6 x (kept links - posed scans + clusters): about 1 when the links'
covariances are honest, below 1 when they are pessimistic, above 1 when the links disagree more
than their covariances allow. Without redundancy (no cycle) there is none.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ndt_cli.ndt.result import RegistrationResult
from ndt_cli.pipeline.graph import components
from ndt_cli.pipeline.link_use import link_covariance
from ndt_cli.pipeline.result import ChainResult
from ndt_cli.pipeline.verify import EdgeState

KEPT = (EdgeState.CONFIRMED, EdgeState.USED)
FREE_M = 1.0  # m: a direction known worse than this is shown as free


@dataclass(frozen=True)
class Strength:
    """1-sigma (m) of the source scanner's position in the target's frame, along the line
    between the scanners, across it (horizontal) and up."""

    along: float
    across: float
    up: float

    def as_mm(self) -> tuple[float, float, float]:
        return 1000 * self.along, 1000 * self.across, 1000 * self.up

    def describe(self) -> str:
        """``along 3 mm, across 2 mm, up 4 mm`` (``free`` beyond :data:`FREE_M`)."""
        words = []
        for name, v in (("along", self.along), ("across", self.across), ("up", self.up)):
            words.append(f"{name} {'free' if v > FREE_M else f'{1000 * v:.0f} mm'}")
        return ", ".join(words)


def link_strength(r: RegistrationResult) -> Strength:
    """The :class:`Strength` of a registration (see the module docstring)."""
    cov = link_covariance(r)[3:, 3:]  # translation, source reduced axes (right perturbation)
    R = r.level_target @ r.T_reduced[:3, :3]  # source reduced axes -> target levelled axes
    C = R @ cov @ R.T
    d = (r.level_target @ r.T_target_source[:3, 3])[:2]
    apart = np.linalg.norm(d)  # m; on one spot: the horizontal axis of most error is "along"
    along = d / apart if apart >= 0.5 else np.linalg.eigh(C[:2, :2])[1][:, 1]
    axes = (np.array([*along, 0.0]), np.array([-along[1], along[0], 0.0]), np.array([0, 0, 1.0]))
    return Strength(*(float(np.sqrt(max(u @ C @ u, 0.0))) for u in axes))


@dataclass(frozen=True)
class NetworkNumbers:
    """Counts of the registrations and links of a campaign, the residuals of its checked
    links (cm, deg; None without one) and its a-posteriori standard deviation of unit weight
    (None without redundancy)."""

    tried: int
    registered: int
    in_network: int
    kept: int
    confirmed: int
    not_checked: int
    rejected: int
    not_used: int
    left_out: int
    max_cm: float | None
    rms_cm: float | None
    max_deg: float | None
    rms_deg: float | None
    sigma0: float | None
    redundancy: int


def _sigma0(result: ChainResult) -> tuple[float | None, int]:
    """sqrt(sum chi2 / redundancy) of the kept links, and the redundancy."""
    fits = result.solution.links
    kept = [
        (k, f) for k, f in zip(result.links, fits, strict=True) if f.state in KEPT and f.residual
    ]
    if not kept:
        return None, 0
    nodes = sorted({v for k, _ in kept for v in (k.target, k.source)})
    at = {v: i for i, v in enumerate(nodes)}
    labels = components(len(nodes), [(at[k.target], at[k.source]) for k, _ in kept])
    redundancy = 6 * (len(kept) - len(nodes) + len(set(labels.tolist())))
    if redundancy <= 0:
        return None, 0
    chi2 = sum(f.residual.chi2 for _, f in kept)
    return float(np.sqrt(chi2 / redundancy)), redundancy


def network_numbers(result: ChainResult) -> NetworkNumbers:
    """The :class:`NetworkNumbers` of a campaign's result."""
    states = [f.state for f in result.solution.links]
    checked = [
        f.residual for f in result.solution.links if f.state is EdgeState.CONFIRMED and f.residual
    ]
    cm = np.array([100 * r.translation_m for r in checked])
    deg = np.array([r.rotation_deg for r in checked])
    every = [*result.links, *(t.link for t in result.tried)]
    sigma0, redundancy = _sigma0(result)

    def stat(v: np.ndarray, f) -> float | None:
        return float(f(v)) if len(v) else None

    def rms(v: np.ndarray) -> float:
        return np.sqrt(np.mean(v**2))

    return NetworkNumbers(
        tried=len(every),
        registered=sum(k.result is not None for k in every),
        in_network=len(result.links),
        kept=sum(s in KEPT for s in states),
        confirmed=states.count(EdgeState.CONFIRMED),
        not_checked=states.count(EdgeState.USED),
        rejected=states.count(EdgeState.REJECTED),
        not_used=states.count(EdgeState.UNUSED),
        left_out=len(result.tried),
        max_cm=stat(cm, np.max),
        rms_cm=stat(cm, rms),
        max_deg=stat(deg, np.max),
        rms_deg=stat(deg, rms),
        sigma0=sigma0,
        redundancy=redundancy,
    )
