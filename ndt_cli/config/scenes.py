"""The settings that suit a kind of scene: the defaults suit streets; interiors get their own.

An interior is small and regular: a ceiling at 2.5-4 m leaves no slice at 4, 8 or 12 m; rooms
and corridors 2-6 m wide need cells and a search pixel finer than a street's facades do; a
room repeated along a corridor, or a corridor turned by 180 degrees, is a second pose as good
as the first, which a 8 m exclusion would hide and NDT's evidence (biased to poses that put
the scanners close together, where both see the most) cannot tell apart.
:func:`for_scene` applies :data:`INDOOR` to the keys a configuration left at their defaults.
"""

from __future__ import annotations

from typing import Any

from ndt_cli.config.schema import Config, from_dict

# key: value indoors. Each with its reason:
INDOOR: dict[str, Any] = {
    # skip links too: every scan on a cycle (bridges are not trusted indoors, below)
    "scene.radius_factor": 3.0,
    # a room seen only through its doorway fits no scan: no sign the walk's order is wrong
    # (counted against it, most floors were judged no walk, and then no bridge is trusted)
    "scene.unplaced_doubt_walk": False,
    # below any ceiling; 0.5 m cuts desks and chairs, 1-2 m walls, doors, shelves, columns
    "slices.heights": [0.5, 1.0, 1.5, 2.0],
    "slices.thickness": 0.2,  # door jambs and pilasters are 0.1-0.2 m deep
    "grid.cell_sizes": [2.0, 1.0, 0.5, 0.25],  # a corridor is 2-3 m wide
    "source.voxel": 0.05,
    "search.bnb_resolution": 0.25,
    "search.bnb_window": 25.0,  # scans of one floor stand within 25 m of each other
    "search.bnb_start_cell": 1.0,
    "search.bnb_exclusion": 1.5,  # a room is 3-4 m wide: a pose slid by one is a candidate
    "search.bnb_candidates": 24,
    "search.translation_range": 12.0,
    "search.translation_step": 3.0,
    # NDT's evidence favours poses that put the scanners close together (each scan's dense near
    # field meets the other's): the true pose had 0.3-0.9 of a wrong one's
    "quality.max_ambiguity": 0.5,
    # one registration alone proves nothing where rooms repeat: a scan is ok only on a cycle
    "quality.trust_bridges": False,
    # the halves of a symmetric floor: two weak links (each kept with 19-49 % of the evidence
    # of a pose the free space refuted) agreed on the far half turned by 180 degrees
    "quality.weak_links_join": False,
    # but a link between corridor neighbours doubted only because a pose the free space refuted
    # had more evidence (it put the scanners closer together) stands on the walk's word when its
    # own pose is clear of the free space by a margin: a tenth of the gate's share below
    "quality.walk_vouch_free_space": 0.0005,
    # right poses of simulated interiors put at most 0.15 % of the points into free space, the
    # wrong ones that no rival named 0.6-4 % (a real robot's room scans put 2 % there: suspect)
    "quality.max_free_space_around": 0.005,
    # NDT at 0.25 m cells leaves ICP a few centimetres and hundredths of a degree; in an open
    # hall of desks ICP turned a right pose by 0.87 degrees, alike in two links that agreed
    "refine.max_correction": 0.5,
}


def for_scene(cfg: Config, kind: str) -> Config:
    """``cfg`` with the settings of ``kind`` ("street": unchanged; "indoor": :data:`INDOOR`
    for every key still at its default) and ``scene.kind`` set to it."""
    data = cfg.to_dict()
    data["scene"]["kind"] = kind
    if kind == "indoor":
        defaults = Config().to_dict()
        for name, value in INDOOR.items():
            section, key = name.split(".")
            if data[section][key] == defaults[section][key]:
                data[section][key] = value
    return from_dict(data)
