"""report.html: one self-contained page per reconstruction, opened in a real browser.

The browser tests drive Debian's Chromium through its chromedriver (Selenium, nothing
downloaded); they skip where either is absent.  One simulated drogue fit (the session's)
serves every test here.
"""

from __future__ import annotations

import dataclasses
import re
import shutil
from pathlib import Path

import pytest

from cpas_ocp.reports.report import write_report

pytestmark = pytest.mark.slow  # fits of a whole phase, a browser

CHROMIUM = next((p for p in ("/usr/bin/chromium", "/usr/bin/chromium-browser")
                 if Path(p).is_file()), shutil.which("chromium"))
CHROMEDRIVER = next((p for p in ("/usr/bin/chromedriver", "/usr/lib/chromium/chromedriver")
                     if Path(p).is_file()), shutil.which("chromedriver"))


@pytest.fixture(scope="module")
def report(drogue_fit, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The drogue fit's report folder, one parameter put on its bound (a flagged row)."""
    fit, cov, _ = drogue_fit(1)
    name = next(n for n in fit.free if n.startswith("t_start"))
    held = dataclasses.replace(cov, at_bound=[name])
    return write_report(fit, held, tmp_path_factory.mktemp("html") / "report")


def test_the_page_is_self_contained_and_carries_the_tables(report, drogue_fit) -> None:
    fit, _, _ = drogue_fit(1)
    page = (report / "report.html").read_text()
    # Offline: no script or stylesheet fetched from anywhere, plotly.js embedded.
    assert not re.search(r"<script[^>]+src=", page)
    assert not re.search(r"<link[^>]+href=", page)
    assert "Plotly.newPlot" in page
    assert len(page) > 3_000_000  # plotly.js itself is several MB
    for name in fit.free:
        assert f"<td>{name}</td>" in page
    flagged = re.findall(r"<tr class=flagged><td>([^<]+)</td>", page)
    assert len(flagged) == 1 and flagged[0].startswith("t_start")
    assert re.search(r"on its (lower|upper) bound \([^<]*\)</td>", page)
    assert "identifiability:" in page
    sensors = dict.fromkeys(r.sensor for r in fit.residuals if r.sensor not in fit.pseudo_sensors)
    for sensor in sensors:
        assert f"{sensor}: model against measurement" in page
    assert "canopy drag areas" in page
    # The drogue manifest is in US customary units: the table says so.
    assert "<td>ft²</td>" in page and "US customary" in page
    assert "Interactive plots: report.html" in (report / "report.md").read_text()


def test_observed_events_are_tabled_against_the_model(drogue_fit) -> None:
    import numpy as np

    from cpas_ocp.estimation.estimator import EVENTS, SensorResidual
    from cpas_ocp.reports.display_units import display_units
    from cpas_ocp.reports.report import reconstruction_page
    fit, cov, _ = drogue_fit(1)
    # The drogue model observes no event times; two are added as the fit would see them.
    events = [SensorResidual(EVENTS, name, np.array([t]), np.array([t]), np.array([m]),
                             np.array([0.01])) for name, t, m in
              (("full_open[drogue1,stage1]", 2.10, 2.095), ("disreef[drogue1,stage2]", 7.00, 6.9))]
    seen = dataclasses.replace(fit, residuals=[*fit.residuals, *events])
    page = reconstruction_page(seen, cov, None, display_units(fit.test)).html()
    assert "Events: observed against the model" in page
    assert "<td>full_open[drogue1,stage1]</td><td class=n>2.1</td><td class=n>2.095</td>" in page
    # 10 sigma off: the row is flagged; 0.5 sigma: not.
    assert "<tr class=flagged><td>disreef[drogue1,stage2]</td>" in page
    assert "<tr><td>full_open[drogue1,stage1]</td>" in page


@pytest.fixture(scope="module")
def browser():
    """Headless Chromium driven by Debian's chromedriver; skips where either is absent."""
    webdriver = pytest.importorskip("selenium.webdriver")
    if CHROMIUM is None or CHROMEDRIVER is None:
        pytest.skip("Chromium and chromedriver are not installed (Debian: apt-get install "
                    "chromium chromium-driver); the browser test needs both")
    from selenium.webdriver.chrome.service import Service
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                 "--disable-gpu", "--window-size=1400,1000"):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(executable_path=CHROMEDRIVER), options=options)
    driver.set_script_timeout(30)
    yield driver
    driver.quit()


def _range(driver, div: str, axis: str) -> list[float]:
    return driver.execute_script(
        f"return document.getElementById('{div}')._fullLayout['{axis}'].range.slice();")


def test_the_page_renders_and_zooms_in_a_browser(report, browser, drogue_fit) -> None:
    fit, _, _ = drogue_fit(1)
    browser.get((report / "report.html").as_uri())
    plots = browser.execute_script(
        "return Array.from(document.querySelectorAll('div.js-plotly-plot')).map(d => "
        "[d.id, d.data.length, d.querySelectorAll('.scatterlayer .trace').length, "
        "d.querySelectorAll('svg.main-svg').length, d.dataset.xaxis]);")
    sensors = {r.sensor for r in fit.residuals if r.sensor not in fit.pseudo_sensors}
    assert len(plots) == len(sensors) + 1  # one per sensor, and the drag areas
    for div, traces, drawn, svgs, _ in plots:
        assert traces > 0 and drawn == traces and svgs > 0, div
    severe = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert not severe, severe

    # Zoom into the opening: a relayout of one plot's time axis; every plot follows.
    first, other = plots[0], plots[-1]
    before = _range(browser, other[0], other[4])
    browser.execute_async_script(
        "const done = arguments[arguments.length - 1];"
        f"Plotly.relayout('{first[0]}', {{'{first[4]}.range': [1.0, 1.7]}}).then(() => "
        "setTimeout(done, 200));")
    assert _range(browser, first[0], first[4]) == pytest.approx([1.0, 1.7])
    assert _range(browser, first[0], "xaxis") == pytest.approx([1.0, 1.7])  # panels shared
    assert _range(browser, other[0], other[4]) == pytest.approx([1.0, 1.7])
    assert before != pytest.approx([1.0, 1.7])

    # A box zoom dragged with the mouse across the bottom panel narrows the time axis.
    from selenium.webdriver.common.action_chains import ActionChains
    browser.execute_async_script(
        "const done = arguments[arguments.length - 1];"
        f"Plotly.relayout('{first[0]}', {{'{first[4]}.autorange': true}}).then(() => "
        "setTimeout(done, 200));")
    full = _range(browser, first[0], first[4])
    area = browser.find_elements(
        "css selector", f"#{first[0]} .draglayer .nsewdrag")[-1]
    width = area.size["width"]
    ActionChains(browser).move_to_element_with_offset(area, -width // 4, 0).click_and_hold() \
        .move_by_offset(width // 8, 0).move_by_offset(width // 8, 5).release().perform()
    browser.execute_async_script("setTimeout(arguments[arguments.length - 1], 300);")
    zoomed = _range(browser, first[0], first[4])
    assert zoomed[1] - zoomed[0] < 0.5 * (full[1] - full[0])
    assert full[0] < zoomed[0] < zoomed[1] < full[1]
    assert _range(browser, other[0], other[4]) == pytest.approx(zoomed)

    # The mouse wheel zooms too: plotly shrinks the span by about 10 % a notch.
    from selenium.webdriver.common.actions.wheel_input import ScrollOrigin
    for _ in range(3):
        ActionChains(browser).scroll_from_origin(ScrollOrigin.from_element(area), 0, -300) \
            .perform()
        browser.execute_async_script("setTimeout(arguments[arguments.length - 1], 300);")
    wheeled = _range(browser, first[0], first[4])
    assert wheeled[1] - wheeled[0] < 0.85 * (zoomed[1] - zoomed[0])
    assert _range(browser, other[0], other[4]) == pytest.approx(wheeled)
    severe = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert not severe, severe


@pytest.fixture(scope="module")
def diagnosis_folder(drogue_fit, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The diagnosis folder of the drogue fit's residuals (their windows and signatures;
    no effect refitted, which is what `diagnose` adds and this page only prints)."""
    from cpas_ocp.discrepancy.diagnosis import Diagnosis
    from cpas_ocp.discrepancy.residual_diagnosis import diagnose_residuals
    from cpas_ocp.inference.diagnostics import window_statistics
    from cpas_ocp.inference.phase_windows import phase_windows
    from cpas_ocp.reports.discrepancy_report import write_diagnosis
    fit, cov, _ = drogue_fit(1)
    windows = phase_windows(fit)
    diag = Diagnosis(fit, windows, window_statistics(fit, windows), [],
                     diagnose_residuals(fit, windows, 0.01))
    return write_diagnosis(diag, cov, tmp_path_factory.mktemp("diag") / "diagnosis")


def test_the_diagnosis_page_has_the_verdict_the_windows_and_the_plots(diagnosis_folder,
                                                                     drogue_fit) -> None:
    fit, _, _ = drogue_fit(1)
    page = (diagnosis_folder / "diagnosis.html").read_text()
    assert "<h2>Verdict</h2>" in page and "Residuals per sensor channel and phase window" in page
    windows = (diagnosis_folder / "windows.csv").read_text().splitlines()
    rows = re.findall(r"<tr><td>(riser_drogue1|gps|imu|riser_drogue2)</td>", page)
    assert len(rows) == len(windows) - 1  # every window of windows.csv, in the table
    # The RMS is shown in display units (US customary here), named in its own column.
    assert "<td>lbf</td>" in page and "<td>ft/s</td>" in page
    sensors = {r.sensor for r in fit.residuals if r.sensor not in fit.pseudo_sensors}
    for sensor in sensors:
        assert page.count(f"{sensor}: model against measurement") == 1
    assert "inflation</span>" in page  # the windows' colours explained


def test_the_comparison_page_shows_both_models_and_the_test(drogue_fit, tmp_path) -> None:
    from cpas_ocp.inference.model_comparison import Comparison, LikelihoodRatio
    from cpas_ocp.io.model_spec import spec_of_test
    from cpas_ocp.reports.discrepancy_report import write_comparison
    fit, cov, _ = drogue_fit(1)
    spec = spec_of_test(fit.test)
    lr = LikelihoodRatio(statistic=1.5, dof=2)
    comparison = Comparison(("A", "B"), (spec, spec), (fit, fit), (cov, cov), lr,
                            "A is nested in B")
    out = write_comparison(comparison, tmp_path / "cmp")
    page = (out / "comparison.html").read_text()
    assert str(lr) in page and "A is nested in B" in page
    assert "Parameters: A" in page and "Parameters: B" in page
    for sensor in {r.sensor for r in fit.residuals if r.sensor not in fit.pseudo_sensors}:
        assert f"{sensor}: normalised residuals, A and B" in page


def test_the_diagnosis_page_renders_in_a_browser(diagnosis_folder, browser) -> None:
    browser.get((diagnosis_folder / "diagnosis.html").as_uri())
    plots = browser.execute_script(
        "return Array.from(document.querySelectorAll('div.js-plotly-plot')).map(d => "
        "[d.data.length, d.querySelectorAll('.scatterlayer .trace').length, "
        "d.querySelectorAll('.shapelayer path').length]);")
    assert plots
    for traces, drawn, shapes in plots:
        assert traces > 0 and drawn == traces and shapes > 0  # bands and windows drawn
    severe = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert not severe, severe


def test_a_large_series_is_drawn_in_full_with_webgl_and_said_so(browser, tmp_path) -> None:
    """A channel of a long descent at a high rate: every sample kept, drawn with WebGL."""
    import numpy as np

    from cpas_ocp.reports.html_page import LARGE_TRACE, Page, sensor_figure
    from cpas_ocp.reports.report_data import ChannelSeries
    rng = np.random.default_rng(3)
    n = LARGE_TRACE + 5_000
    t = np.linspace(0.0, 245.0, n)
    model = np.sin(t)
    measured = model + 0.1 * rng.standard_normal(n)
    page = Page("a long descent")
    sensor_figure(page, "accel", [ChannelSeries("accel", "acceleration", "m/s^2", t, measured,
                                                model, (measured - model) / 0.1)])
    path = page.write(tmp_path / "large.html")
    assert f"accel.acceleration ({n:,} points)" in path.read_text()
    browser.get(path.as_uri())
    drawn = browser.execute_script(
        "const g = document.querySelector('div.js-plotly-plot');"
        "return [g._fullData.map(d => d.type), g._fullData.map(d => d.x.length),"
        " g.querySelectorAll('canvas').length];")
    assert drawn[0] == ["scattergl"] * 3 and drawn[1] == [n] * 3 and drawn[2] > 0
    severe = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert not severe, severe


# --- pages that lead with the answer --------------------------------------------------

def test_the_reconstruction_page_leads_with_the_drag_areas(report, browser, drogue_fit) -> None:
    fit, _, _ = drogue_fit(1)
    browser.get((report / "report.html").as_uri())
    headings = browser.execute_script(
        "return Array.from(document.querySelectorAll('h2')).map(h => h.textContent);")
    assert headings[0] == "The answer", headings
    assert headings.index("The answer") < headings.index("Parameters")
    first = browser.execute_script(
        "const t = document.querySelector('table'); return [t.previousElementSibling && "
        "t.previousElementSibling.textContent, Array.from(t.querySelectorAll('tbody tr'))"
        ".map(r => Array.from(r.cells).map(c => c.textContent))];")
    rows = first[1]
    areas = [n for n in fit.free if n.startswith("CdS[")]
    assert [r[0] for r in rows] == areas  # the first table on the page: the drag areas
    for row in rows:  # each to its sigma: as many decimals as two digits of the sigma take
        value, sigma = row[1], row[2]
        assert len(value.split(".")[-1]) == len(sigma.split(".")[-1]), row


@pytest.fixture(scope="module")
def wind_report(problem_folder, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A `rocket_steady` test reconstructed with the wind process: a report whose model has
    process knots (still air, so the curve is flat within its band; what is tested is how
    the knots are drawn)."""
    import json

    import cpas_ocp as co

    folder = problem_folder("rocket_steady", 1)
    manifest = json.loads((folder / "manifest.json").read_text())
    model = tmp_path_factory.mktemp("wind") / "model.json"
    model.write_text(json.dumps({**manifest["model"],
                                 "effects": ["wind_process", *manifest["model"]["effects"]]}))
    out = model.parent / "report"
    co.reconstruct(folder, model=model, out=out)
    return out


def test_the_air_motion_is_a_curve_with_its_band_not_a_list(wind_report, browser) -> None:
    page = (wind_report / "report.html").read_text()
    assert "<h2>The air&#x27;s motion</h2>" in page or "<h2>The air's motion</h2>" in page
    assert not re.search(r"<td>wind_\w+\[\d+\]</td>", page)  # the knots drawn, not tabled
    browser.get((wind_report / "report.html").as_uri())
    traces = browser.execute_script(
        "const h = Array.from(document.querySelectorAll('h2')).find(h => "
        "h.textContent.startsWith('The air')); let e = h.nextElementSibling; "
        "while (e && !e.querySelector('div.js-plotly-plot')) e = e.nextElementSibling; "
        "const d = e.querySelector('div.js-plotly-plot'); "
        "return d._fullData.map(t => [t.name || '', t.fill || '', t._length]);")
    assert any(fill == "tonexty" for _, fill, _ in traces)  # the band
    assert any(name == "estimate at the knots" and n > 3 for name, _, n in traces)
    headings = browser.execute_script(
        "return Array.from(document.querySelectorAll('h2')).map(h => h.textContent);")
    assert headings[0] == "The answer"


@pytest.fixture(scope="module")
def discovery_folder(problem_folder, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A two-step chain of real `fbcp` fits (`cheap_discovery`), written as `discover`
    writes it."""
    from cpas_ocp.cli import main
    from tests.cheap_discovery import cheap

    out = tmp_path_factory.mktemp("discovery") / "chain"
    patch = pytest.MonkeyPatch()
    cheap(patch)
    try:
        assert main(["discover", str(problem_folder("fbcp", 1)), "--out", str(out),
                     "--max-steps", "2"]) == 0
    finally:
        patch.undo()
    return out


def test_the_discovery_page_opens_with_chi_square_step_by_step(discovery_folder,
                                                               browser) -> None:
    import json

    steps = json.loads((discovery_folder / "discovery.json").read_text())["steps"]
    browser.get((discovery_folder / "discovery.html").as_uri())
    opening = browser.execute_script(
        "const h = document.querySelector('h2'); const d = document.querySelector("
        "'div.js-plotly-plot'); const t = document.querySelector('table'); return [h.textContent,"
        " d._fullData.map(s => [s.name || '', s._length]), t.querySelectorAll('tbody tr').length,"
        " Array.from(t.querySelectorAll('th')).map(c => c.textContent),"
        " document.documentElement.scrollWidth <= window.innerWidth];")
    heading, traces, rows, header, fits = opening
    assert heading == "The error, step by step"
    chain = [n for name, n in traces if name == "χ²/dof after the step"]
    assert chain == [len(steps)] and any(name == "the noise's 95 % range" for name, _ in traces)
    assert rows == len(steps) and "share of the excess removed" in header
    assert fits  # no horizontal scrollbar: the chain is a table, not a wide <pre>
    page = (discovery_folder / "discovery.html").read_text()
    assert not re.search(r"<pre>\s*step\s+added", page)  # the text table is not pasted in
