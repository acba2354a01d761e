"""Convex hulls, their growth by an engineering factor, and rejection sampling inside them.

The containment test is checked against scipy's Delaunay triangulation (an
independent point-location), never against itself.  "Fills the hull" is a
chi-square test of the counts in the cells of a grid over the bounding box,
against the exact area/volume of each cell's intersection with the grown hull
(scipy's HalfspaceIntersection), failing only below p = 1e-3.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats
from scipy.optimize import linprog
from scipy.spatial import ConvexHull, Delaunay, HalfspaceIntersection

from cpas_ocp.campaign.distributions import fit_dispersion
from cpas_ocp.campaign.hulls import (
    CHUNK,
    ENGINEERING_FACTOR,
    PILOT_ENGINEERING_FACTOR,
    Hull,
    box_corners,
    dispersion_caps,
    sample_in_hull,
)

P_MIN = 1e-3
MIN_EXPECTED = 5.0  # chi-square cells with fewer expected counts are pooled


def finite_mass_points() -> np.ndarray:
    """25 synthetic (n, expopen) points, correlated, in different units and spreads."""
    rng = np.random.default_rng(101)
    g = rng.multivariate_normal([0.0, 0.0], [[1.0, 0.6], [0.6, 1.0]], 25)
    return np.column_stack([10.0 + 1.5 * g[:, 0], 1.2 + 0.25 * g[:, 1]])


def infinite_mass_points() -> np.ndarray:
    """30 synthetic (Ck, n_p, expopen) points: high Ck goes with high n_p and expopen."""
    rng = np.random.default_rng(102)
    cov = [[1.0, 0.6, 0.4], [0.6, 1.0, 0.3], [0.4, 0.3, 1.0]]
    g = rng.multivariate_normal([0.0, 0.0, 0.0], cov, 30)
    return np.column_stack([1.5 + 0.12 * g[:, 0], 5.0 + 1.2 * g[:, 1], 2.0 + 0.4 * g[:, 2]])


@pytest.fixture(scope="module")
def hull2() -> Hull:
    return Hull.from_points(finite_mass_points(), ["n", "expopen"])


@pytest.fixture(scope="module")
def hull3() -> Hull:
    return Hull.from_points(infinite_mass_points(), ["Ck", "n_p", "expopen"])


def inside_by_delaunay(vertices: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Independent point location: inside the triangulation of the hull's vertices."""
    return Delaunay(vertices).find_simplex(x) >= 0


def cell_measure(halfspaces: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> float:
    """Area/volume of {A x + b <= 0} intersected with the box [lower, upper]."""
    d = lower.size
    eye = np.eye(d)
    box = np.vstack([np.column_stack([eye, -upper]), np.column_stack([-eye, lower])])
    hs = np.vstack([halfspaces, box])
    a, b = hs[:, :-1], hs[:, -1]
    norms = np.linalg.norm(a, axis=1)
    # Chebyshev centre: max r subject to a_i x + r |a_i| <= -b_i
    res = linprog(np.r_[np.zeros(d), -1.0], A_ub=np.column_stack([a, norms]), b_ub=-b,
                  bounds=[(None, None)] * d + [(0.0, None)])
    if res.status == 2:  # infeasible: the cell does not meet the hull
        return 0.0
    assert res.status == 0
    if res.x[-1] < 1e-9 * np.min(upper - lower):
        return 0.0
    corners = HalfspaceIntersection(hs, res.x[:-1]).intersections
    return float(ConvexHull(corners).volume)


def chi_square_fill(hull: Hull, points: np.ndarray, cells_per_axis: int) -> float:
    """p-value of the cell counts of `points` against the hull's exact cell measures."""
    lower, upper = hull.bounding_box()
    d = hull.dimension
    edges = [np.linspace(lower[i], upper[i], cells_per_axis + 1) for i in range(d)]
    halfspaces = hull.halfspaces()
    expected, observed = [], []
    counts, _ = np.histogramdd(points, bins=edges)
    for index in np.ndindex(*(cells_per_axis,) * d):
        lo = np.array([edges[i][k] for i, k in enumerate(index)])
        hi = np.array([edges[i][k + 1] for i, k in enumerate(index)])
        expected.append(cell_measure(halfspaces, lo, hi) / hull.volume)
        observed.append(counts[index])
    expected_counts = np.array(expected) * points.shape[0]
    observed_counts = np.array(observed)
    assert np.sum(expected) == pytest.approx(1.0, abs=1e-9)  # the cells tile the hull
    assert np.all(observed_counts[expected_counts == 0.0] == 0)
    small = expected_counts < MIN_EXPECTED
    e = np.r_[expected_counts[~small], expected_counts[small].sum()]
    o = np.r_[observed_counts[~small], observed_counts[small].sum()]
    keep = e > 0
    assert keep.sum() > 5  # enough cells for the test to mean something
    return float(stats.chisquare(o[keep], e[keep]).pvalue)


# --- growth ---------------------------------------------------------------------------

@pytest.mark.parametrize("factor", [ENGINEERING_FACTOR, PILOT_ENGINEERING_FACTOR])
@pytest.mark.parametrize("points", [finite_mass_points, infinite_mass_points])
def test_growth_scales_area_and_volume_by_factor_to_the_dimension(factor, points) -> None:
    x = points()
    d = x.shape[1]
    hull = Hull.from_points(x)
    grown = hull.grow(factor)
    assert hull.volume == pytest.approx(ConvexHull(x).volume, rel=1e-12)
    assert grown.volume / hull.volume == pytest.approx((1 + factor) ** d, rel=1e-12)
    # the grown vertices themselves span that volume
    assert ConvexHull(grown.vertices).volume == pytest.approx(
        (1 + factor) ** d * ConvexHull(x).volume, rel=1e-9)
    assert grown.growth == pytest.approx(factor)


def test_each_vertex_moves_away_from_the_centroid_by_the_factor(hull3: Hull) -> None:
    x = infinite_mass_points()
    centroid = x.mean(axis=0)
    grown = hull3.grow(0.10)
    before = hull3.vertices - centroid
    after = grown.vertices - centroid
    assert np.allclose(after, 1.10 * before, rtol=1e-13, atol=0.0)  # same direction, 10 % further
    assert np.all(grown.contains(x)) and np.all(grown.contains(grown.vertices))


# --- containment ----------------------------------------------------------------------

@pytest.mark.parametrize("name", ["hull2", "hull3"])
def test_contains_agrees_with_delaunay(name: str, request: pytest.FixtureRequest) -> None:
    grown: Hull = request.getfixturevalue(name).grow(ENGINEERING_FACTOR)
    lower, upper = grown.bounding_box()
    span = upper - lower
    n = 2 * CHUNK + 1234  # several blocks of the containment test, the last one partial
    x = lower - 0.1 * span + 1.2 * span * np.random.default_rng(7).random((n, grown.dimension))
    fast = grown.contains(x)
    reference = inside_by_delaunay(grown.vertices, x)
    assert 0.05 < fast.mean() < 0.95  # both outcomes well represented
    assert np.array_equal(fast, reference)


@pytest.mark.parametrize("name", ["hull2", "hull3"])
def test_point_just_outside_each_facet_is_rejected(name: str,
                                                   request: pytest.FixtureRequest) -> None:
    grown: Hull = request.getfixturevalue(name).grow(ENGINEERING_FACTOR)
    z_vertices = (grown.vertices - grown.center) / grown.scale
    step = 1e-6  # in units of each parameter's test range, far above the 1e-9 tolerance
    for normal_and_offset in grown.equations:
        normal, offset = normal_and_offset[:-1], normal_and_offset[-1]
        on_facet = np.abs(z_vertices @ normal + offset) < 1e-9
        assert on_facet.sum() >= grown.dimension
        z_mid = z_vertices[on_facet].mean(axis=0)
        outside = grown.center + grown.scale * (z_mid + step * normal)
        inside = grown.center + grown.scale * (z_mid - step * normal)
        assert not grown.contains(outside)
        assert grown.contains(inside)


def test_grown_hull_accepts_what_the_tests_hull_rejects(hull2: Hull) -> None:
    vertex = hull2.vertices[0]
    beyond = hull2.center + 1.05 * (vertex - hull2.center)  # 5 % beyond an outermost point
    assert not hull2.contains(beyond)
    assert hull2.grow(0.10).contains(beyond)
    assert not hull2.grow(0.04).contains(beyond)


def test_corners_of_the_caps_box_are_rejected(hull3: Hull) -> None:
    x = infinite_mass_points()
    dispersions = [fit_dispersion(name, x[:, i]) for i, name in enumerate(hull3.names)]
    grown = hull3.grow(ENGINEERING_FACTOR)
    corners = box_corners(*dispersion_caps(dispersions))
    assert corners.shape == (8, 3)
    assert not np.any(grown.contains(corners))
    assert not np.any(inside_by_delaunay(grown.vertices, corners))
    # e.g. low n_p, low expopen and high Ck together
    assert not grown.contains([dispersions[0].upper_cap, dispersions[1].lower_cap,
                               dispersions[2].lower_cap])


# --- sampling -------------------------------------------------------------------------

@pytest.mark.parametrize(("name", "cells_per_axis"), [("hull2", 6), ("hull3", 4)])
def test_uniform_draws_are_inside_and_fill_the_grown_hull(name: str, cells_per_axis: int,
                                                          request: pytest.FixtureRequest) -> None:
    grown: Hull = request.getfixturevalue(name).grow(ENGINEERING_FACTOR)
    n = 20_000
    draws = sample_in_hull(grown, n, seed=3)
    assert draws.points.shape == (n, grown.dimension)
    assert np.all(inside_by_delaunay(grown.vertices, draws.points))
    # acceptance of uniform box draws estimates volume(hull)/volume(box), binomial noise
    lower, upper = grown.bounding_box()
    fraction = grown.volume / np.prod(upper - lower)
    se = np.sqrt(fraction * (1 - fraction) / draws.n_drawn)
    assert abs(draws.acceptance - fraction) < 4 * se
    assert chi_square_fill(grown, draws.points, cells_per_axis) > P_MIN


def test_uniform_draws_reach_the_boundary_of_the_grown_hull(hull2: Hull) -> None:
    """The draws' own hull misses about (2/3) r ln(n)/n of an r-gon's area (Renyi-Sulanke)."""
    grown = hull2.grow(ENGINEERING_FACTOR)
    n = 20_000
    draws = sample_in_hull(grown, n, seed=4)
    r = grown.vertices.shape[0]
    expected_missing = 2.0 / 3.0 * r * np.log(n) / n
    ratio = ConvexHull(draws.points).volume / grown.volume
    assert 1.0 - 3.0 * expected_missing < ratio <= 1.0


def test_dispersion_draws_are_inside_and_some_are_rejected(hull3: Hull) -> None:
    x = infinite_mass_points()
    dispersions = [fit_dispersion(name, x[:, i]) for i, name in enumerate(hull3.names)]
    grown = hull3.grow(ENGINEERING_FACTOR)
    draws = sample_in_hull(grown, 10_000, seed=5, dispersions=dispersions)
    assert draws.points.shape == (10_000, 3)
    assert np.all(inside_by_delaunay(grown.vertices, draws.points))
    lo, hi = dispersion_caps(dispersions)
    assert np.all((draws.points >= lo) & (draws.points <= hi))
    # the independent draws fall outside the grown hull often enough to matter
    rng = np.random.default_rng(6)
    free = np.column_stack([d.sample(50_000, rng) for d in dispersions])
    outside = 1.0 - inside_by_delaunay(grown.vertices, free).mean()
    assert outside > 0.01
    se = np.sqrt(outside * (1 - outside) / draws.n_drawn)
    assert abs((1.0 - draws.acceptance) - outside) < 4 * se + 4 * np.sqrt(
        outside * (1 - outside) / free.shape[0])


def test_sampling_is_reproducible_by_seed(hull2: Hull) -> None:
    grown = hull2.grow(PILOT_ENGINEERING_FACTOR)
    a = sample_in_hull(grown, 1_000, seed=9)
    b = sample_in_hull(grown, 1_000, seed=np.random.default_rng(9))
    c = sample_in_hull(grown, 1_000, seed=10)
    assert np.array_equal(a.points, b.points) and a.n_drawn == b.n_drawn
    assert not np.array_equal(a.points, c.points)


def test_dispersions_that_miss_the_hull_stop_with_an_error(hull2: Hull) -> None:
    far = [fit_dispersion("n", [100.0, 101.0, 102.0]), fit_dispersion("expopen", [5.0, 6.0, 7.0])]
    with pytest.raises(RuntimeError, match="rarely fall in the hull"):
        sample_in_hull(hull2, 100, seed=1, dispersions=far, max_draws=50_000)


def test_dispersions_in_another_order_are_refused(hull2: Hull) -> None:
    x = finite_mass_points()
    swapped = [fit_dispersion("expopen", x[:, 1]), fit_dispersion("n", x[:, 0])]
    with pytest.raises(ValueError, match="parameter order"):
        sample_in_hull(hull2, 10, seed=1, dispersions=swapped)


# --- bad input ------------------------------------------------------------------------

@pytest.mark.parametrize(("points", "message"), [
    ([[1.0, 2.0], [2.0, 3.5]], "at least 3 points"),
    ([[1.0, 2.0, 3.0], [2.0, 1.0, 3.0], [1.0, 1.0, 1.0]], "at least 4 points"),
    ([[0.0, 1.0], [1.0, 3.0], [2.0, 5.0], [3.0, 7.0]], "collinear"),
    ([[0.0, 0.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 2.0], [1.0, 1.0, 3.0], [0.5, 0.2, 0.9]],
     "coplanar"),
    ([[0.0, 0.0], [1.0, 0.0], [0.0, np.nan]], "NaN"),
    ([[0.0, 0.0], [1.0, 0.0], [0.0, np.inf]], "infinite"),
    ([[0.0, 1.0], [1.0, 1.0], [2.0, 1.0]], "same value on every test"),
    ([1.0, 2.0, 3.0], "array"),
    ([[1.0], [2.0]], "at least 2 parameters"),
])
def test_degenerate_points_raise_a_clear_error(points: list, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        Hull.from_points(points)


def test_contains_refuses_nan_and_wrong_width(hull2: Hull) -> None:
    with pytest.raises(ValueError, match="NaN"):
        hull2.contains([[1.0, np.nan]])
    with pytest.raises(ValueError, match="2 columns"):
        hull2.contains([[1.0, 2.0, 3.0]])


def test_negative_factor_is_refused(hull2: Hull) -> None:
    with pytest.raises(ValueError, match="engineering factor"):
        hull2.grow(-0.1)
