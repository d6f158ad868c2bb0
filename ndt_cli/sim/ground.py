"""The ground of a simulated street: a smooth quadratic surface in the world frame.

``z = grade * x + cross_fall * y + curve * x**2 / 2 + crown * y**2 / 2`` (metres; world x, y).
``grade`` and ``cross_fall`` are slopes (rise over run: 0.08 is an 8 % grade), ``curve`` is
the change of grade per metre along x (a vertical curve: a crest when negative, a sag when
positive), ``crown`` the same across (a cambered carriageway that falls to both kerbs when
negative: a cross slope of ``c`` at ``y = k`` m needs ``crown = -c / k``). The default is the
flat plane z = 0, which the simulator treats as before (bit-identical scans).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Ground:
    """A quadratic ground surface (see the module docstring); slopes in m/m, curvatures in 1/m."""

    grade: float = 0.0
    cross_fall: float = 0.0
    curve: float = 0.0
    crown: float = 0.0

    @property
    def flat(self) -> bool:
        return self == Ground()

    def z(self, x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
        """Ground height (m) at world (x, y)."""
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        return (
            self.grade * x
            + self.cross_fall * y
            + 0.5 * self.curve * x * x
            + 0.5 * self.crown * y * y
        )

    def normal(self, x: float, y: float) -> np.ndarray:
        """Unit upward normal of the ground at world (x, y)."""
        gx = self.grade + self.curve * x
        gy = self.cross_fall + self.crown * y
        n = np.array([-gx, -gy, 1.0])
        return n / np.linalg.norm(n)

    def hit(self, origin: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """Distance (m) along unit rays ``dirs`` from ``origin`` (above the ground) to the first
        crossing of the ground; inf where a ray never reaches it.

        Along a ray ``p = o + t d`` the gap ``f(t) = z_ground(p) - p_z`` is a quadratic
        ``A t^2 + B t + C`` with ``C < 0`` (the origin is above the ground); the first positive
        root is the hit (roots from the stable form ``q = -(B + sign(B) sqrt(B^2 - 4AC)) / 2``).
        """
        o = np.asarray(origin, dtype=float)
        dx, dy, dz = dirs[:, 0], dirs[:, 1], dirs[:, 2]
        gx = self.grade + self.curve * o[0]
        gy = self.cross_fall + self.crown * o[1]
        A = 0.5 * (self.curve * dx * dx + self.crown * dy * dy)
        B = gx * dx + gy * dy - dz
        C = float(self.z(o[0], o[1])) - o[2]
        disc = B * B - 4.0 * A * C
        real = disc >= 0.0
        root = np.sqrt(np.where(real, disc, 0.0))
        q = -0.5 * (B + np.where(B >= 0.0, root, -root))
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = np.where(A != 0.0, q / A, np.inf)
            t2 = np.where(q != 0.0, C / q, np.inf)
        t1 = np.where(real & (t1 > 0.0), t1, np.inf)
        t2 = np.where(real & (t2 > 0.0), t2, np.inf)
        return np.minimum(t1, t2)
