"""Convex hulls of reconstructed inflation parameters, and Monte Carlo draws restricted to them.

Paper Sections IV.C (infinite mass, 3-D), V (Pilots) and VI (Mains, 2-D):
certain combinations of inflation parameters (every one at its cap at once,
e.g. low n_p, low expopen and high Ck) give loads outside flight experience.
The tests' points are bounded by their convex hull, in 2-D (n, expopen:
finite-mass canopies) or 3-D (Ck, n_p, expopen: infinite-mass canopies), the
hull is grown by an engineering factor (10 %, 15 % for Pilots) "by extending
each outermost test point", and Monte Carlo draws of all the parameters
together are rejected and redrawn whenever they fall outside the grown hull.

Conventions used here:

* Normalised coordinates.  The parameters have different units and spreads,
  so every computation runs in z = (x - c) / s, with c the centroid (mean) of
  the test points and s each parameter's test range (max - min over the
  tests).  Qhull's facet normals are unit vectors in z, so the facet
  inequality A z + b <= tol has `tol` in units of each parameter's test
  range, and the degeneracy check (collinear, coplanar points) is scale-free.
* Growth.  Each hull vertex v is moved away from the centroid c of the test
  points by the factor times its distance from c:
  v' = c + (1 + f) (v - c).  This is a homothety about c: it maps the hull
  onto the hull of the moved vertices, multiplies the area (2-D) by
  (1 + f)^2 and the volume (3-D) by (1 + f)^3, and it is the same whatever
  the scaling of each axis, so the grown hull does not depend on the units
  or on the normalisation.  A vertex far from the centroid moves further
  than one close to it; the buffer is not a uniform offset of the boundary.
* Drawing.  `sample_in_hull` draws every parameter of a candidate point at
  once, either each from its capped `Dispersion`, independently (the Monte
  Carlo inputs: the accepted points follow the product of the capped
  distributions restricted to the grown hull, hence to the intersection of
  the hull and the caps box), or, without dispersions, uniformly in the grown
  hull's bounding box (the accepted points are then uniform in the grown
  hull).  A candidate outside the grown hull is rejected and redrawn until
  `n` points are accepted; accepted points are kept in draw order, so a seed
  gives the same inputs.  The rejection changes the marginals: one
  parameter's accepted draws no longer follow its fitted distribution (values
  that only occur with extreme companions are thinned out);
  `HullSample.acceptance` tells how much was rejected.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from cpas_ocp.campaign.distributions import Dispersion, generator

ENGINEERING_FACTOR = 0.10        # customary buffer beyond the outermost test points
PILOT_ENGINEERING_FACTOR = 0.15  # Pilots: fewer data, higher uncertainty
INSIDE_TOL = 1e-9                # facet tolerance, in units of each parameter's test range
RANK_TOL = 1e-9                  # smallest singular value / largest, below it points are degenerate
CHUNK = 65_536                   # points per block in the containment test


class DegenerateHull(ValueError):
    """Test points that span fewer dimensions than their parameters (collinear, coplanar,
    or a parameter constant over the tests): they have no hull with a volume."""


def check_points(points: np.ndarray | Sequence[Sequence[float]],
                 names: Sequence[str] | None = None) -> tuple[np.ndarray, tuple[str, ...]]:
    """The test points as an (m, d) float array and their parameter names.

    Raises ValueError naming the problem: not 2-D, fewer than 2 parameters,
    NaN or infinite values, fewer than d + 1 points, a parameter with the same
    value on every test, or points that are collinear (2-D) or coplanar (3-D),
    i.e. span less than d dimensions.
    """
    x = np.asarray(points, dtype=float)
    if x.ndim != 2:
        raise ValueError(f"points must be an (n_tests, n_parameters) array, got shape {x.shape}")
    m, d = x.shape
    labels = tuple(names) if names is not None else tuple(f"p{i}" for i in range(d))
    if len(labels) != d:
        raise ValueError(f"{len(labels)} names given for {d} parameters")
    if d < 2:
        raise ValueError(f"a hull needs at least 2 parameters, got {d}")
    if np.isnan(x).any():
        row, col = np.argwhere(np.isnan(x))[0]
        raise ValueError(f"points contain NaN (test {row}, parameter {labels[col]})")
    if not np.isfinite(x).all():
        row, col = np.argwhere(~np.isfinite(x))[0]
        raise ValueError(f"points contain an infinite value (test {row}, parameter {labels[col]})")
    if m < d + 1:
        raise ValueError(f"a {d}-D hull needs at least {d + 1} points, got {m}")
    spread = np.ptp(x, axis=0)
    if np.any(spread <= 0.0):
        flat = [labels[i] for i in np.flatnonzero(spread <= 0.0)]
        raise DegenerateHull(f"parameter(s) {', '.join(flat)} have the same value on every test: "
                         f"the points span fewer than {d} dimensions")
    z = (x - x.mean(axis=0)) / spread
    singular = np.linalg.svd(z, compute_uv=False)
    rank = int(np.sum(singular > RANK_TOL * singular[0]))
    if rank < d:
        shape = {1: "collinear", 2: "coplanar"}.get(rank, f"in a {rank}-D subspace")
        raise DegenerateHull(f"the {m} points are {shape} (they span {rank} of {d} dimensions): "
                         "their convex hull has no area/volume")
    return x, labels


@dataclass(frozen=True)
class Hull:
    """A convex hull of test points in d parameters, possibly grown about their centroid.

    ``vertices`` (k, d) and ``center`` (d,) are in the parameters' own units;
    ``scale`` (d,) is each parameter's test range, the unit of the
    normalised coordinates z = (x - center) / scale; ``equations`` (F, d + 1)
    are the facets [A | b] in z, unit outward normals, with A z + b <= 0
    inside; ``volume`` is the area (2-D) or volume (3-D) in the parameters' own
    units (the product of their units); ``growth`` is the engineering factor
    applied so far (0 for the tests' own hull).
    """

    names: tuple[str, ...]
    vertices: np.ndarray
    center: np.ndarray
    scale: np.ndarray
    equations: np.ndarray
    volume: float
    growth: float = 0.0

    @classmethod
    def from_points(cls, points: np.ndarray | Sequence[Sequence[float]],
                    names: Sequence[str] | None = None) -> Hull:
        """The convex hull of the test points (rows: tests, columns: parameters `names`)."""
        x, labels = check_points(points, names)
        center = x.mean(axis=0)
        scale = np.ptp(x, axis=0)
        z = (x - center) / scale
        try:
            hull = ConvexHull(z)
        except QhullError as exc:  # the rank check above should have caught it
            raise DegenerateHull(f"the points have no {x.shape[1]}-D convex hull: {exc}"
                                 ) from exc
        # Qhull triangulates facets, so coplanar simplices repeat an equation.
        equations = np.unique(np.round(hull.equations, 12), axis=0)
        return cls(names=labels, vertices=x[hull.vertices], center=center, scale=scale,
                   equations=equations, volume=float(hull.volume * np.prod(scale)))

    @property
    def dimension(self) -> int:
        """Number of parameters d."""
        return len(self.names)

    def grow(self, factor: float = ENGINEERING_FACTOR) -> Hull:
        """The hull with every vertex moved away from the centroid by `factor` times its distance.

        v' = c + (1 + factor)(v - c); the facets keep their normals and their
        offsets b scale by (1 + factor); the volume scales by (1 + factor)^d.
        """
        if not np.isfinite(factor) or factor < 0.0:
            raise ValueError(f"engineering factor must be a finite number >= 0, got {factor}")
        k = 1.0 + factor
        equations = self.equations.copy()
        equations[:, -1] *= k
        return replace(self, vertices=self.center + k * (self.vertices - self.center),
                       equations=equations, volume=self.volume * k ** self.dimension,
                       growth=(1.0 + self.growth) * k - 1.0)

    def halfspaces(self) -> np.ndarray:
        """Facets [A' | b'] in the parameters' own units: A' x + b' <= 0 inside (rows not unit)."""
        a = self.equations[:, :-1] / self.scale
        b = self.equations[:, -1] - a @ self.center
        return np.column_stack([a, b])

    def contains(self, x: np.ndarray | Sequence[float], tol: float = INSIDE_TOL) -> np.ndarray:
        """Whether each point (rows of `x`, or one point) is inside: (A z + b)_f <= tol for all f.

        `tol` is in units of each parameter's test range.  Vectorised over the
        points, one facet at a time, in blocks of `CHUNK` points with in-place
        arithmetic: A z = (A / scale)(x - center), so no normalised copy of
        the points is made.  Raises ValueError for NaN or a wrong width.
        """
        pts = np.asarray(x, dtype=float)
        single = pts.ndim == 1
        pts = np.atleast_2d(pts)
        d = self.dimension
        if pts.ndim != 2 or pts.shape[1] != d:
            raise ValueError(f"points must have {d} columns "
                             f"({', '.join(self.names)}), got shape {np.shape(x)}")
        if np.isnan(pts).any():
            raise ValueError("points to test contain NaN")
        normals = self.equations[:, :-1] / self.scale
        limits = tol - self.equations[:, -1]
        shifted = np.ascontiguousarray((pts - self.center).T)  # (d, n)
        n = pts.shape[0]
        inside = np.ones(n, dtype=bool)
        total = np.empty(min(n, CHUNK))
        term = np.empty_like(total)
        for start in range(0, n, CHUNK):
            block = shifted[:, start:start + CHUNK]
            m = block.shape[1]
            acc, s, t = inside[start:start + m], total[:m], term[:m]
            for normal, limit in zip(normals, limits, strict=True):
                np.multiply(block[0], normal[0], out=s)
                for i in range(1, d):
                    np.multiply(block[i], normal[i], out=t)
                    s += t
                acc &= s <= limit
        return inside[0:1].reshape(()) if single else inside

    def bounding_box(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper corner of the hull's axis-aligned bounding box (own units)."""
        return self.vertices.min(axis=0), self.vertices.max(axis=0)


def box_corners(lower: np.ndarray | Sequence[float],
                upper: np.ndarray | Sequence[float]) -> np.ndarray:
    """The 2^d corners of the box [lower, upper]: every parameter at one of its bounds at once."""
    lo, hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    if lo.shape != hi.shape or lo.ndim != 1:
        raise ValueError(f"lower and upper must be 1-D of the same length, got {lo.shape}, "
                         f"{hi.shape}")
    return np.array([np.where(pick, hi, lo)
                     for pick in itertools.product((False, True), repeat=lo.size)])


def dispersion_caps(dispersions: Sequence[Dispersion]) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper caps of each dispersion: the box every Monte Carlo draw lies in."""
    return (np.array([d.lower_cap for d in dispersions]),
            np.array([d.upper_cap for d in dispersions]))


@dataclass(frozen=True)
class HullSample:
    """Accepted Monte Carlo inputs (n, d) in the hull's parameter order, and the draws they took."""

    names: tuple[str, ...]
    points: np.ndarray
    n_drawn: int

    @property
    def acceptance(self) -> float:
        """Fraction of candidate points that fell inside the grown hull."""
        return self.points.shape[0] / self.n_drawn if self.n_drawn else float("nan")


def sample_in_hull(hull: Hull, n: int, seed: np.random.Generator | int,
                   dispersions: Sequence[Dispersion] | None = None,
                   max_draws: int | None = None) -> HullSample:
    """`n` points inside `hull` by rejection; all parameters of a candidate are drawn together.

    With `dispersions` (one per hull parameter, same order; names checked
    against the hull's when they are set) every coordinate is drawn from its
    capped distribution, independently; without, the candidates are uniform in
    the hull's bounding box.  Candidates outside the hull (facet test with the
    default tolerance) are rejected and redrawn, in batches sized from the
    acceptance seen so far, until `n` are accepted; the first `n` accepted, in
    draw order, are returned, and ``n_drawn`` counts the candidates up to the
    n-th acceptance.  Raises RuntimeError after `max_draws`
    candidates (default 1000 n + 100,000), e.g. when the dispersions' caps
    box does not meet the hull.
    """
    if n < 0:
        raise ValueError(f"number of points must be >= 0, got {n}")
    rng = generator(seed)
    d = hull.dimension
    if dispersions is not None:
        if len(dispersions) != d:
            raise ValueError(f"{len(dispersions)} dispersions for a {d}-D hull "
                             f"({', '.join(hull.names)})")
        mismatched = [(h, disp.name) for i, (h, disp)
                      in enumerate(zip(hull.names, dispersions, strict=True))
                      if h != f"p{i}" and disp.name != h]
        if mismatched:
            raise ValueError("dispersions are not in the hull's parameter order: "
                             + ", ".join(f"{h} vs {m}" for h, m in mismatched))

        def draw(m: int) -> np.ndarray:
            return np.column_stack([disp.sample(m, rng) for disp in dispersions])
    else:
        lower, upper = hull.bounding_box()

        def draw(m: int) -> np.ndarray:
            return lower + (upper - lower) * rng.random((m, d))

    limit = 1000 * n + 100_000 if max_draws is None else max_draws
    accepted: list[np.ndarray] = []
    n_accepted = 0
    n_drawn = 0
    while n_accepted < n:
        rate = max(n_accepted / n_drawn, 1e-3) if n_drawn else 0.5
        batch = int(min(max((n - n_accepted) / rate * 1.1 + 64, 1024), 4 * CHUNK))
        if n_drawn + batch > limit:
            raise RuntimeError(f"only {n_accepted} of {n} points accepted after {n_drawn} "
                               f"draws (limit {limit}): the draws rarely fall in the hull")
        candidates = draw(batch)
        inside = hull.contains(candidates)
        hits = np.flatnonzero(inside)
        need = n - n_accepted
        if hits.size >= need:  # count the draws up to the n-th acceptance only
            hits = hits[:need]
            n_drawn += int(hits[-1]) + 1
        else:
            n_drawn += batch
        accepted.append(candidates[hits])
        n_accepted += hits.size
    points = np.concatenate(accepted, axis=0) if accepted else np.empty((0, d))
    return HullSample(names=hull.names, points=points, n_drawn=n_drawn)
