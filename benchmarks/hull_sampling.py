"""Benchmark: 200,000 three-parameter Monte Carlo inputs drawn by hull rejection.

Synthetic infinite-mass test points (Ck, n_p, expopen; CPAS-like magnitudes,
NOT CPAS data) are fitted with capped distributions, bounded by their convex
hull, and the hull is grown by the 10 % engineering factor.  Timed in this one
process, each the best of `--repeats` runs:

* baseline: 200,000 x 3 plain uniform draws in the grown hull's bounding box;
* 200,000 x 3 inverse-CDF draws of the three capped distributions, no hull;
* the product: 200,000 points accepted inside the grown hull, candidates
  drawn from the capped distributions (`sample_in_hull` with dispersions);
* the same with candidates uniform in the bounding box;
* point location of the product's candidate count with scipy's Delaunay
  triangulation (``find_simplex``), and with a naive per-point loop over the
  facet equations, the latter timed on 20,000 points and scaled linearly.

Ratios are against the baseline.  The target for the product is under 2 s.

    python benchmarks/hull_sampling.py [--n 200000] [--repeats 3] [--seed 1]
"""

from __future__ import annotations

from collections.abc import Callable

import harness
import numpy as np
from scipy.spatial import Delaunay

from cpas_ocp.campaign.distributions import fit_dispersion
from cpas_ocp.campaign.hulls import ENGINEERING_FACTOR, INSIDE_TOL, Hull, sample_in_hull

TARGET_S = 2.0
NAIVE_POINTS = 20_000


def synthetic_points(seed: int) -> np.ndarray:
    """30 synthetic (Ck, n_p, expopen) points, correlated."""
    rng = np.random.default_rng(seed)
    cov = [[1.0, 0.6, 0.4], [0.6, 1.0, 0.3], [0.4, 0.3, 1.0]]
    g = rng.multivariate_normal([0.0, 0.0, 0.0], cov, 30)
    return np.column_stack([1.5 + 0.12 * g[:, 0], 5.0 + 1.2 * g[:, 1], 2.0 + 0.4 * g[:, 2]])


def best_of(repeats: int, run: Callable[[], object]) -> tuple[float, object]:
    """Shortest wall time (s) of `repeats` runs and the last run's result."""
    timer, result = harness.Timer(), None
    for _ in range(repeats):
        with timer("run"):
            result = run()
    return min(timer.laps.get("run", [float("inf")])), result


def naive_contains(hull: Hull, x: np.ndarray) -> np.ndarray:
    """One point at a time: every facet inequality of the point, in a Python loop."""
    a, b = hull.equations[:, :-1], hull.equations[:, -1]
    out = np.empty(x.shape[0], dtype=bool)
    for i, point in enumerate(x):
        out[i] = bool(np.all(a @ ((point - hull.center) / hull.scale) + b <= INSIDE_TOL))
    return out


def main() -> None:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the draws")
    parser.add_argument("--n", type=int, default=200_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    n = args.n

    points = synthetic_points(102)
    names = ["Ck", "n_p", "expopen"]
    dispersions = [fit_dispersion(name, points[:, i]) for i, name in enumerate(names)]
    hull = Hull.from_points(points, names)
    grown = hull.grow(ENGINEERING_FACTOR)
    lower, upper = grown.bounding_box()
    for d in dispersions:
        print(d)
    print(f"hull: {hull.vertices.shape[0]} vertices, {grown.equations.shape[0]} facets; "
          f"grown by {ENGINEERING_FACTOR:.0%}: volume x{grown.volume / hull.volume:.4f}")

    t_box, _ = best_of(args.repeats, lambda: lower + (upper - lower)
                       * np.random.default_rng(args.seed).random((n, 3)))

    def capped_draws() -> np.ndarray:
        rng = np.random.default_rng(args.seed)
        return np.column_stack([d.sample(n, rng) for d in dispersions])

    t_disp, _ = best_of(args.repeats, capped_draws)
    t_hull, drawn = best_of(args.repeats, lambda: sample_in_hull(
        grown, n, args.seed, dispersions=dispersions))
    t_hull_box, drawn_box = best_of(args.repeats, lambda: sample_in_hull(grown, n, args.seed))

    candidates = capped_draws()
    n_candidates = drawn.n_drawn
    extra = np.column_stack([d.sample(max(n_candidates - n, 0), np.random.default_rng(2))
                             for d in dispersions])
    candidates = np.vstack([candidates, extra])[:n_candidates]
    triangulation = Delaunay(grown.vertices)
    t_delaunay, _ = best_of(args.repeats, lambda: triangulation.find_simplex(candidates) >= 0)
    t_vector, inside = best_of(args.repeats, lambda: grown.contains(candidates))
    subset = candidates[:NAIVE_POINTS]
    t_naive_sub, naive = best_of(1, lambda: naive_contains(grown, subset))
    assert np.array_equal(naive, inside[:NAIVE_POINTS])
    t_naive = t_naive_sub * n_candidates / NAIVE_POINTS

    rows = [
        (f"baseline: {n:,} x 3 uniform draws in the box", t_box),
        (f"{n:,} x 3 capped-distribution draws, no hull", t_disp),
        (f"hull rejection, capped distributions ({drawn.n_drawn:,} drawn, "
         f"acceptance {drawn.acceptance:.3f})", t_hull),
        (f"hull rejection, uniform box ({drawn_box.n_drawn:,} drawn, "
         f"acceptance {drawn_box.acceptance:.3f})", t_hull_box),
        (f"facet test alone, vectorised, {n_candidates:,} points", t_vector),
        (f"Delaunay find_simplex, {n_candidates:,} points", t_delaunay),
        (f"naive per-point loop, {n_candidates:,} points (from {NAIVE_POINTS:,})", t_naive),
    ]
    print(f"\n{'':74s} {'seconds':>9s} {'x baseline':>11s}")
    for label, seconds in rows:
        print(f"{label:74s} {seconds:9.4f} {harness.ratio_text(seconds, t_box, '11.1f')}")
    verdict = "under" if t_hull < TARGET_S else "OVER"
    print(f"\n{n:,} hull-rejection draws: {t_hull:.3f} s, {verdict} the {TARGET_S:.0f} s target")
    harness.report("hull_sampling", n=n, repeats=args.repeats,
                   timings=[{"what": label, "seconds": seconds,
                             "x_baseline": harness.ratio(seconds, t_box)}
                            for label, seconds in rows],
                   hull_rejection_s=t_hull, target_s=TARGET_S, under_target=t_hull < TARGET_S)


if __name__ == "__main__":
    main()
