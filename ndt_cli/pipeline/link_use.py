"""How far the network may use a link, from what its registration found: whether its transform
can be tested at all (usable), checked around a cycle (firm, determined), chosen among rivals
(contested) or trusted on the walk's word though its gate doubted it; the kept pose's share of
the evidence; and its covariance between the scans' reduced frames.

Plain predicates of one link each (the network's decisions are in
:mod:`ndt_cli.pipeline.members` and :mod:`ndt_cli.pipeline.solution`).
"""

from __future__ import annotations

import numpy as np

from ndt_cli.ndt.result import RegistrationResult, Status
from ndt_cli.pipeline.covariance import DEFAULT_MAX_SIGMA, icp_covariance, ndt_covariance
from ndt_cli.pipeline.links import Link

USABLE = (Status.OK, Status.SUSPECT, Status.DEGENERATE)  # links whose transform can be tested
# (unless the data refute it: ndt_cli.ndt.quality.verdict_of)


def usable(link: Link) -> bool:
    """A link whose transform the network can test: registered, and not refuted by its data
    (:func:`ndt_cli.ndt.quality.verdict_of`)."""
    return link.status in USABLE and not link.result.refuted


def firm(link: Link) -> bool:
    """A usable link without rivals: the network can check it against others around a cycle,
    whatever its own gate said (:mod:`ndt_cli.pipeline.verify`)."""
    return usable(link) and not link.result.rivals


def determined(link: Link) -> bool:
    """A firm link whose pose the data fix in every direction (no weak one): a cycle of
    links can check it horizontally. A weak link (a corridor's) fixes its rotation and height
    only, and a rotation by 180 degrees agrees with a wrong rival chosen on the same cycle:
    on an office floor one such link, 40 m off and turned, made three scans ok and wrong."""
    return firm(link) and link.result.weak_direction is None


def contested(link: Link) -> bool:
    """A usable link with rivals whose poses the data fix in every direction: a cycle of firm
    links can choose among them (:mod:`ndt_cli.pipeline.members`)."""
    return usable(link) and bool(link.result.rivals) and link.result.weak_direction is None


def link_covariance(r: RegistrationResult) -> np.ndarray:
    """6x6 covariance of a link between the reduced frames (GTSAM Pose3 tangent, see
    :mod:`ndt_cli.pipeline.covariance`): from ICP's normal matrix when ICP refined it, else
    from the NDT Hessian. A degenerate link says nothing of where the scans are horizontally,
    whatever the small curvature along its weak direction suggests: a corridor's links all
    settle where their starts put them and so agree with each other, and the weak directions
    that different links find differ by degrees, so that together they would seem to pin the
    corridor's axis down. Its horizontal translation is "unknown" (as
    :data:`~ndt_cli.pipeline.covariance.DEFAULT_MAX_SIGMA`); its rotation and height count."""
    refined = r.icp_hessian is not None and np.isfinite(r.icp_rms) and r.icp_centroid is not None
    if refined and not r.icp_rejected:
        cov = icp_covariance(r.icp_hessian, r.icp_centroid, r.T_reduced, r.icp_rms)
    else:
        cov = ndt_covariance(
            r.hessian, r.T_reduced, level_target=r.level_target, level_source=r.level_source
        )
    if r.status is Status.DEGENERATE:
        flat = r.level_target.T[:, :2]  # the target's horizontal axes, in its reduced frame
        h = r.T_reduced[:3, :3].T @ flat  # as the source body axes see them
        cov = cov + DEFAULT_MAX_SIGMA**2 * np.pad(h @ h.T, ((3, 0), (3, 0)))
    return cov


def kept_share(link: Link) -> float:
    """The kept pose's evidence over the most of any of the link's candidates (1: the pose of
    most evidence was kept, or the link has no candidates)."""
    found = () if link.result is None else link.result.candidates
    most = max((c.evidence for c in found), default=0.0)
    return found[0].evidence / most if most > 0.0 else 1.0


def doubted_only_for_evidence(link: Link, min_kept_evidence: float, clear: float) -> bool:
    """A determined link (:func:`determined`) whose gate doubted it for one reason alone: a
    pose the free space refuted had more evidence (under ``min_kept_evidence`` of it was kept,
    "it may be a pose slid along the scene"), while the kept pose puts at most ``clear`` of
    its points in front of all the other scanner saw around them (0: never such a link).

    Such a doubt is what NDT's evidence gives a right pose wherever the scene repeats: a pose
    that puts the two scanners closer together meets more of each scan's dense near field, and
    scores more: of 34 right links so doubted on the office floors of the trust sweep, 31 had
    every refuted pose of more evidence put the scanners closer together (and so had 20 of 30
    wrong ones: closeness alone tells nothing). Between neighbours along the walk, whose order
    says they stand near each other, the doubt is answered (:mod:`ndt_cli.pipeline.members`):
    the 13 right ones put at most 0.02 % of their points there, the two wrong ones 0.49 % and
    0.06 % (that one degenerate too)."""
    if clear <= 0.0 or link.status is not Status.SUSPECT or not determined(link):
        return False
    r = link.result
    alone = len(r.warnings) == 1 and kept_share(link) < min_kept_evidence
    return alone and bool(np.isfinite(r.free_space_around)) and r.free_space_around <= clear
