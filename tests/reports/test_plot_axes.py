"""Every figure of the reports can be drawn into a user's axes: each `*_axes` function of
`reports.plots` takes `ax` or `axes`, draws there and returns what it drew into, and the
`plot_*` functions that write files only save what an `*_axes` function drew."""

from __future__ import annotations

import ast
import inspect

import matplotlib.pyplot as plt

from cpas_ocp.estimation.reduction import reduce_and_guess, stage_starts
from cpas_ocp.io.model_spec import baseline_spec
from cpas_ocp.reports import plots
from cpas_ocp.reports.display_units import display_units
from cpas_ocp.reports.reduction_report import reduction_axes


def test_every_axes_function_takes_the_axes_to_draw_into() -> None:
    drawers = [f for name, f in inspect.getmembers(plots, inspect.isfunction)
               if name.endswith("_axes") and f.__module__ == plots.__name__]
    assert len(drawers) >= 10, [f.__name__ for f in drawers]
    for f in drawers:
        given = set(inspect.signature(f).parameters)
        assert given & {"ax", "axes"}, f.__name__


def test_no_plot_function_makes_a_figure_of_its_own() -> None:
    """A `plot_*` function saves the figure an `*_axes` function drew: none calls
    plt.subplots or plt.figure itself."""
    tree = ast.parse(inspect.getsource(plots))
    makers = []
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and node.name.startswith("plot_"):
            for call in ast.walk(node):
                if (isinstance(call, ast.Call) and isinstance(call.func, ast.Attribute)
                        and call.func.attr in ("subplots", "figure")):
                    makers.append(node.name)
    assert not makers, makers


def test_figures_are_drawn_into_the_axes_given(drogue_fit) -> None:
    fit, _, _ = drogue_fit(1)
    fig, grid = plt.subplots(2, 2)
    sensor = next(s for s in fit.sensors if sum(r.sensor == s for r in fit.residuals) == 1)
    drawn = plots.residual_comparison_axes(fit, fit, sensor, ("A", "B"), axes=grid[:1])
    assert drawn is not None and drawn[0, 0] is grid[0, 0] and grid[0, 0].has_data()
    ax = plots.discovery_axes(["baseline", "+ added_mass"], [3.1, 1.0], [5.0, 1.1],
                              ax=grid[1, 0])
    assert ax is grid[1, 0] and len(ax.lines) == 3
    units = display_units(fit.test)
    guess, red = reduce_and_guess(fit.test, baseline_spec().model(fit.test))
    ax = reduction_axes(fit.test, red, stage_starts(fit.test, guess), units, ax=grid[1, 1])
    assert ax is grid[1, 1] and ax.has_data()
    plt.close(fig)
