"""The drawing of a system that has no hand-drawn scene: its kinematic tree.

A derivation that records the mechanism's points and links (every MJCF or URDF model) is
drawn as bars between the points, each centre of mass a disc whose area grows with the
body's share of the mass, each joint anchor a pivot. The picture is a projection onto the
plane the motion is in (nothing moves along the third world axis), else the one in which
the points move most (a vertical one when it shows at least 80 % of the most); the motion
is sampled at fixed, seeded states around the operating point, so the view stays the same
from frame to frame, whatever run is shown.
"""

from __future__ import annotations

import math

import numpy as np

from equilibrist.viz.drawing import COLORS, Scene, Shape, bar, circle

# The three candidate views: the two world axes shown (right, up) and the
# name of the plane.
_PLANES = (("xz", 0, 2), ("yz", 1, 2), ("xy", 0, 1))
# Motion counts as planar when the least-moving world axis holds at most
# this share of it.
PLANAR = 1e-6
_LINK_COLORS = (COLORS["body"], COLORS["link"], COLORS["link2"], COLORS["mark"], COLORS["wheel"])


def can_draw(system: object) -> bool:
    """Whether *system*'s model records the points a generic drawing needs."""
    # Scenes take any object with a system's attributes; one without a
    # compiled model (a stand-in) has no points to draw.
    functions = getattr(system, "functions", None)
    return functions is not None and len(functions.POINTS) > 0


class GenericScene(Scene):
    """The kinematic tree of a system, seen in the plane that shows the most motion."""

    def __init__(self, system: object) -> None:
        super().__init__(system)
        functions = system.functions  # type: ignore[attr-defined]
        self._points_fn = functions.points
        self.point_names: tuple[str, ...] = tuple(functions.POINTS)
        self.links: tuple[tuple[int, int], ...] = tuple((int(a), int(b)) for a, b in functions.LINKS)
        self._p = np.array(system.p, dtype=np.float64)  # type: ignore[attr-defined]
        samples = self._samples()
        world = np.array([self.positions(x) for x in samples])  # (n, points, 3)
        self.plane, self.right, self.up = self._choose_plane(world)
        self.caption = f"kinematic tree in the {self.plane} plane: joints (black), centres of mass (discs)"
        flat = world[:, :, [self.right, self.up]].reshape(-1, 2)
        span = float(np.ptp(flat, axis=0).max()) if flat.size else 1.0
        self.size = max(span, 1e-3)
        self._sample_extent = (flat.min(axis=0), flat.max(axis=0))
        # Disc sizes: area proportional to each body's mass.
        masses = {n[: -len("_mass")]: v for n, v in self.params.items() if n.endswith("_mass")}
        heaviest = max(masses.values(), default=1.0)
        self.radius = {
            k: 0.045 * self.size * math.sqrt(masses.get(name[: -len("_com")], heaviest) / heaviest)
            for k, name in enumerate(self.point_names) if name.endswith("_com")
        }

    def _samples(self) -> np.ndarray:
        spec = self.system.spec  # type: ignore[attr-defined]
        n = len(self.state_names)
        base = np.zeros(n)
        op = spec.operating_point
        if op is not None:
            for name, value in op.state.items():
                if not isinstance(value, str):
                    base[self._index[name]] = float(value)
        rng = np.random.default_rng(0)
        out = [base]
        for _ in range(40):
            x = base.copy()
            for k, c in enumerate(spec.coordinates):
                if c in spec.region:
                    lo, hi = spec.region[c]
                    half = min((hi - lo) / 2, math.pi)
                else:
                    half = 0.5 if spec.units.get(c) == "rad" else 0.25
                x[k] = base[k] + rng.uniform(-half, half)
            out.append(x)
        return np.array(out)

    def _choose_plane(self, world: np.ndarray) -> tuple[str, int, int]:
        motion = world - world.mean(axis=0, keepdims=True)
        variance = (motion**2).sum(axis=(0, 1))  # per world axis
        # Motion in one plane (a world axis along which nothing moves): that
        # plane, whichever way the rig was drawn (z up, or y up as a
        # planar rig written by hand often is).
        still = int(np.argmin(variance))
        if variance[still] <= PLANAR * float(variance.sum()):
            for name, a, b in _PLANES:
                if still not in (a, b):
                    return name, a, b
        scores = [(variance[a] + variance[b], name, a, b) for name, a, b in _PLANES]
        best = max(s[0] for s in scores)
        # The vertical planes first when they show nearly as much.
        for score, name, a, b in scores:
            if name != "xy" and score >= 0.8 * best:
                return name, a, b
        return "xy", 0, 1

    def positions(self, x: np.ndarray) -> np.ndarray:
        """World positions ``(n_points, 3)`` of the recorded points at state *x*."""
        out = np.empty((len(self.point_names), 3))
        self._points_fn(np.asarray(x, float), self._p, out)
        return out

    def shapes(self, x: np.ndarray, u: np.ndarray | None, trail: np.ndarray | None = None) -> list[Shape]:
        world = self.positions(x)
        pts = world[:, [self.right, self.up]]
        width = 0.035 * self.size
        out: list[Shape] = []
        for k, (a, b) in enumerate(self.links):
            color = _LINK_COLORS[min(k, len(_LINK_COLORS) - 1) % len(_LINK_COLORS)]
            out.append(Shape(f"link_{k}", "fill", bar(pts[a], pts[b], width), color, z=2.0 + 0.01 * k))
        for k, name in enumerate(self.point_names):
            if name.endswith("_com"):
                out.append(Shape(f"com_{name}", "fill", circle(pts[k], self.radius[k], 32),
                                 COLORS["disc"], z=3.0, edge=COLORS["pivot"], width=1.0))
            elif name == "world":
                out.append(Shape("world", "fill", circle(pts[k], 0.03 * self.size, 16),
                                 COLORS["ground"], z=1.5))
            else:
                out.append(Shape(f"joint_{name}", "fill", circle(pts[k], 0.02 * self.size, 16),
                                 COLORS["pivot"], z=4.0))
        return out

    def reach(self, states: np.ndarray) -> tuple[float, float, float, float]:
        lo, hi = self._sample_extent
        pad = 0.08 * self.size
        return (float(lo[0] - pad), float(hi[0] + pad), float(lo[1] - pad), float(hi[1] + pad))
