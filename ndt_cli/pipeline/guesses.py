"""Guesses a surveyor gives a campaign: approximate poses of scans (``--init-poses``: GNSS and
a compass, yesterday's campaign, a placement by hand) and of pairs (``--pairs`` rows with a
pose), with how far they may be off (``--init-sigma``).

A guess never replaces the search: a link with a guess is registered both ways, from the
search and from the guess (:class:`~ndt_cli.ndt.register.Guess`: its first cell set by its
uncertainty), and the result that passes the gate with the higher score at the finest cells is
kept (:func:`better`). A wrong guess therefore cannot make a link ok that the search alone
would not; a right one rescues a pair whose search ends elsewhere. Scans with an approximate
pose are also placed near it: the scans around it are registered to it first.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from ndt_cli.core.transforms import pose2d_matrix, wrap_angle, yaw_of
from ndt_cli.errors import ConfigError, InputError
from ndt_cli.io.matrices import named_rows, read_matrix, rigid_problem
from ndt_cli.ndt.guess import Guess, beyond_text
from ndt_cli.ndt.result import RegistrationResult, Status
from ndt_cli.ndt.rivals import distinct

MAX_COORDINATE_M = 1e8  # m: a projected coordinate is at most tens of millions of metres
MAX_PAIR_M = 10_000.0  # m: scans farther apart share nothing


def parse_sigma(text: str, option: str = "--init-sigma") -> tuple[float, float]:
    """``M,DEG`` checked: metres in (0, 1000], degrees in (0, 180]."""
    try:
        metres, degrees = (float(v) for v in text.split(","))
    except ValueError:
        raise ConfigError(f"{option} must be METRES,DEGREES (e.g. 1,5), got {text!r}") from None
    if not (0 < metres <= 1000 and 0 < degrees <= 180):
        raise ConfigError(
            f"{option}: metres must be in (0, 1000] and degrees in (0, 180], got {text!r}"
        )
    return metres, degrees


def pose_of(numbers: Sequence[str]) -> np.ndarray | None:
    """A pose from 16 numbers (a 4x4, row-major) or 4 (x y z m, yaw degrees); None when the
    fields are neither."""
    try:
        values = [float(v) for v in numbers]
    except ValueError:
        return None
    if not all(np.isfinite(values)):
        return None
    if len(values) == 16:
        return np.array(values).reshape(4, 4)
    if len(values) == 4:
        return pose2d_matrix(values[0], values[1], np.radians(values[3]), values[2])
    return None


def read_init_poses(path: Path, names: Sequence[str]) -> dict[int, np.ndarray]:
    """Approximate ``T_world_scan`` per scan: lines ``NAME`` and 16 numbers (a 4x4, as
    ``poses.txt``) or ``NAME x y z yaw_deg``; NAME a scan's name or campaign index. A line
    naming no scan, of other numbers, or not rigid is an error naming the line."""
    lookup = {n: k for k, n in enumerate(names)}
    out: dict[int, np.ndarray] = {}
    for number, fields in named_rows(path, "initial poses"):
        scan = lookup.get(fields[0])
        if scan is None and fields[0].isascii() and fields[0].isdigit():
            scan = int(fields[0]) if int(fields[0]) < len(names) else None
        if scan is None:
            raise InputError(f"line {number}: no scan named {fields[0]!r}", path)
        T = pose_of(fields[1:])
        if T is None:
            raise InputError(
                f"line {number}: expected a name and 16 numbers (a 4x4) or x y z yaw_deg", path
            )
        problem = rigid_problem(T)
        if problem:
            raise InputError(f"line {number}: {problem}", path)
        if np.abs(T[:3, 3]).max() > MAX_COORDINATE_M:
            far = float(np.abs(T[:3, 3]).max())
            raise InputError(
                f"line {number}: a coordinate of {far:.3g} m is no place on earth", path
            )
        out[scan] = T
    return out


def pair_pose(cells: Sequence[str], folder: Path) -> np.ndarray | None:
    """A pairs-file row's guess of ``T_target_source`` after its two scans: four numbers
    (x y z m, yaw degrees), or the name of a 4x4 file (relative to the pairs file's folder);
    None when the row has none. Raises ValueError with the reason when it is neither."""
    rest = [c for c in cells if c]
    if not rest:
        return None
    if len(rest) == 1:
        path = Path(rest[0]) if Path(rest[0]).is_absolute() else folder / rest[0]
        try:
            T = read_matrix(path)
        except InputError as exc:
            raise ValueError(str(exc)) from None
    else:
        T = pose_of(rest) if len(rest) == 4 else None
    if T is None:
        raise ValueError("a guess is x,y,z,yaw_deg or a 4x4 file")
    if np.abs(T[:3, 3]).max() > MAX_PAIR_M:
        raise ValueError(f"a guess puts the scans more than {MAX_PAIR_M:g} m apart")
    return T


def relative(
    poses: Mapping[int, np.ndarray], target: int, source: int, sigma: tuple[float, float]
) -> Guess | None:
    """The guess of ``T_target_source`` two approximate poses give (None unless both have
    one), each within ``sigma`` (m, degrees). The pair's heading is within sqrt(2) times the
    degrees; its position within sqrt(2) times the metres and what the target's heading error
    does to the source's position seen from it: ``d`` m away, ``d`` times that error (5 degrees
    over 90 m: 7.9 m)."""
    if target not in poses or source not in poses:
        return None
    T = np.linalg.inv(poses[target]) @ poses[source]
    d = float(np.hypot(*T[:2, 3]))
    metres = float(np.hypot(sigma[0] * np.sqrt(2.0), d * np.radians(sigma[1])))
    return Guess(T, metres, min(180.0, sigma[1] * np.sqrt(2.0)))


def turned_round(guess: Guess | None) -> Guess | None:
    """The guess of the same link registered the other way round (``T_source_target``)."""
    if guess is None:
        return None
    return Guess(np.linalg.inv(guess.T_target_source), guess.sigma_m, guess.sigma_deg)


def better(
    search: RegistrationResult, guessed: RegistrationResult, guess: Guess | None = None
) -> RegistrationResult:
    """The result kept of a link registered from the search and from a guess: the one the
    gate calls ok, then the higher NDT score at the finest cells (the search's on a tie). The
    two judge each other first: the search's pose beyond the ``guess``'s reach is suspect
    (:func:`against_guess`), and indoors a guess's pose that the search did not end at is not
    ok on its own (:func:`unconfirmed_indoors`)."""
    guessed = unconfirmed_indoors(search, guessed)
    search = against_guess(search, guess)
    if search.ok != guessed.ok:
        return search if search.ok else guessed
    return guessed if guessed.score > search.score else search


def against_guess(result: RegistrationResult, guess: Guess | None) -> RegistrationResult:
    """``result``, suspect when it is ok and its pose is beyond the guess's reach (3 times its
    uncertainty: :func:`~ndt_cli.ndt.guess.beyond_text`). A search that ends 180 degrees from
    a guess within 7 degrees contradicts it: with approximate poses the sweep's office floors
    had three scans ok and turned by 180 degrees through such a link, kept where the guess's
    own result was not confirmed. A guess that lies about its uncertainty makes right links
    suspect too: the warning says how far the data put them from it. A degenerate result
    beyond the reach is suspect as well: the network would still take its rotation and its
    height, and the height of a pose slid 44 m along a 3 % grade is 1.3 m off."""
    if guess is None or result.status not in (Status.OK, Status.DEGENERATE):
        return result
    text = beyond_text(_planar(result.T_target_source), _planar(guess.T_target_source), guess)
    if not text:
        return result
    return replace(result, status=Status.SUSPECT, warnings=(*result.warnings, text))


def _planar(T: np.ndarray) -> np.ndarray:
    """(x, y m, yaw rad) of a 4x4 T_target_source."""
    return np.array([T[0, 3], T[1, 3], yaw_of(T)])


def unconfirmed_indoors(
    search: RegistrationResult, guessed: RegistrationResult
) -> RegistrationResult:
    """``guessed``, suspect when it was registered indoors, is ok, and is not the pose the
    search ended at (a distinct pose, :func:`~ndt_cli.ndt.rivals.distinct`: 0.5 m or 3 degrees
    apart). Indoors one registration's evidence cannot tell the truth from a pose slid by a
    room or across a wall (docs/trust.md), and the guess's refinement sees only the poses near
    it; the search's candidates and the free space judged the whole floor. With approximate
    poses within 1 m and 5 degrees, the sweep's office floors had two scans ok and wrong
    through such links: one 3.9 m along the floor, one 15 cm across a wall."""
    a, b = _planar(search.T_target_source), _planar(guessed.T_target_source)
    if guessed.scene != "indoor" or not guessed.ok or not distinct(a, b):
        return guessed
    text = (
        f"indoors the guess's pose is not confirmed: the search ended "
        f"{np.hypot(*(b[:2] - a[:2])):.2f} m and {abs(np.degrees(wrap_angle(b[2] - a[2]))):.1f} "
        "deg from it"
    )
    return replace(guessed, status=Status.SUSPECT, warnings=(*guessed.warnings, text))


def guess_text(guess: Guess | None) -> str:
    """The guess as part of a link's identity (its stored result depends on it)."""
    if guess is None:
        return ""
    values = " ".join(f"{v:.6f}" for v in np.asarray(guess.T_target_source).ravel())
    return f"\nguess {values} sigma {guess.sigma_m:g} {guess.sigma_deg:g}"
