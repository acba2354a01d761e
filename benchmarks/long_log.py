"""Benchmark: a 10-minute, 100 Hz rocket log with the card's default model (the air's
vertical motion as a wind process), any mix of its channels, imported and
reconstructed from the command line, this tree against an earlier revision.

A seeded point-mass flight (the generator of `cpas_ocp/io/example_flight.py`,
as `long_descent.py` uses it): a 16.9 kg rocket boosted to about 4.4 km above
the pad, an 8 m^2 drogue at apogee (26 s) and a 20 m^2 main at 300 m (599 s),
touchdown at 683 s.  The log holds the barometer (hPa) and optionally the
three-axis accelerometer (g) at 100 Hz and the GNSS altitude at 1 Hz (3 m
noise; the card's lapse rate then "gps", which fits them); its card lists no
effects, so the import writes the rocket default model: the wind process
(knots every 4 s: 165 on this log), the canopies, the sensors (and the
altimeter's bias and lag with a second sensor).  `--no-diameter` leaves the
canopies' diameters out of the card (taken from the descent).

Each case runs `cpas-ocp import` and then `cpas-ocp reconstruct` as separate
processes per code tree, stderr a pipe, and prints per stage the wall time,
the peak resident memory (the child's ru_maxrss from wait4), the exit code and
the progress lines written to stderr during the solve; then the ratios
baseline / this tree.  Each tree runs with a fresh compile cache, `--repeat`
times (the first run evaluates in CasADi's VM while the model compiles; the
next runs on native code).  A run past `--timeout` seconds is stopped and its
ratio printed as a lower bound.

    python benchmarks/long_log.py [--cases baro+accel,baro] [--baseline REV]
                                  [--no-baseline] [--repeat N] [--timeout S]
                                  [--no-diameter] [--seed N]
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from benchmarks import harness  # noqa: E402
from benchmarks.revisions import code_at, run_stage  # noqa: E402
from cpas_ocp.estimation.estimator import Estimator  # noqa: E402
from cpas_ocp.io.example_flight import A_NOISE, SITE, fly, sensor_readings  # noqa: E402
from tests.io.test_rocket_log_import import CARD, COLUMN_MAP  # noqa: E402

BASELINE = "f7978ab"  # before the import merged a series' straight stretches into means
THRUST_N = 4200.0  # boost thrust (N, 2.5 s): apogee about 4.4 km above the pad
CDS_TRUE = {"drogue": 8.0, "main": 20.0}  # the canopies' full drag areas (m^2)
DIAMETER_IN = {"drogue": 120, "main": 200}  # nominal diameters on the card (in)
GNSS_NOISE_M = 3.0  # GNSS altitude noise (m)
CHANNELS = ("baro", "accel", "gnss")
CASES = ("baro+accel", "baro")


def write_log(folder: Path, channels: set[str], seed: int, diameter: bool = True
              ) -> dict[str, float]:
    """The seeded 100 Hz log (log.csv) with `channels` (the barometer always; "accel", the
    three-axis accelerometer; "gnss", the GNSS altitude at 1 Hz), its column map (map.json)
    and a card without a model (card.json) in `folder`; returns the flight's event times (s)."""
    from cpas_ocp.physics.units import G0
    flight = fly(thrust_n=THRUST_N, drogue_delay_s=0.0, cds=CDS_TRUE)
    p, a = sensor_readings(flight, seed)
    rng = np.random.default_rng(seed + 20)
    n = flight.t.size
    fix = np.isclose(flight.t % 1.0, 0.0, atol=1e-6)
    columns = {"t_ms": np.round(1e3 * flight.t).astype(int), "press_hPa": np.round(p / 100.0, 2)}
    column_map = {key: COLUMN_MAP[key] for key in ("recorder", "time", "pressure", "gnss")}
    column_map["gnss"] = dict(column_map["gnss"])
    if "accel" in channels:
        columns.update(ax_g=np.round(rng.normal(0, A_NOISE, n) / G0, 4),
                       ay_g=np.round(-(a + G0) / G0, 4),
                       az_g=np.round(rng.normal(0, A_NOISE, n) / G0, 4))
        column_map["acceleration"] = COLUMN_MAP["acceleration"]
    columns["lat"] = np.where(fix, 32.94 + 1e-5 * flight.t, np.nan)
    columns["lon"] = np.where(fix, -106.9 + 2e-5 * flight.t, np.nan)
    card = json.loads(json.dumps(CARD))
    card.pop("model")
    card["name"] = "long_log"
    if "gnss" in channels:
        columns["alt"] = np.where(fix, SITE.elevation_m + flight.h
                                  + rng.normal(0.0, GNSS_NOISE_M, n), np.nan)
        column_map["gnss"]["altitude"] = {"column": "alt", "unit": "m"}
        card["site"]["lapse_rate"] = "gps"
    for chute in card["parachutes"]:
        if diameter:
            chute["diameter"] = {"value": DIAMETER_IN[chute["name"]], "unit": "in"}
        else:
            chute.pop("diameter")
    folder.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(columns).to_csv(folder / "log.csv", index=False, float_format="%.7g")
    (folder / "map.json").write_text(json.dumps(column_map))
    (folder / "card.json").write_text(json.dumps(card))
    return flight.events


def imported_estimator(seed: int, channels: frozenset[str] = frozenset({"baro", "accel"})
                       ) -> Estimator:
    """The log of `write_log` with `channels`, imported by `cpas-ocp import` in this
    process into a temporary folder, and its estimator under the model the import
    wrote (the rocket default)."""
    from cpas_ocp.api.reconstruction import as_test, build, model_of
    from cpas_ocp.cli import main as cli
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        write_log(folder, set(channels), seed)
        code = cli(["import", str(folder / "log.csv"), "--columns", str(folder / "map.json"),
                    "--card", str(folder / "card.json"), "--out", str(folder / "test")])
        if code:
            raise SystemExit(f"the import failed (exit {code})")
        test = as_test(folder / "test")
        return build(test, model_of(test))


def run_case(code: Path, folder: Path, cache: Path, timeout: float, label: str) -> dict:
    """Import the log in `folder` and reconstruct it with the package of `code`."""
    out = folder / label
    stages = {"import": run_stage(code, ["import", "log.csv", "--columns", "map.json", "--card",
                                         "card.json", "--out", str(out / "test")], cache,
                                  timeout, folder)}
    if stages["import"]["exit"] == 0:
        stages["reconstruct"] = run_stage(code, ["reconstruct", str(out / "test"), "--out",
                                                 str(out / "report")], cache, timeout, folder)
        result = out / "report" / "result.json"
        if result.exists():
            res = json.loads(result.read_text())
            stages["reconstruct"]["fit"] = {
                "status": res["solver"]["status"], "iterations": res["solver"]["iterations"],
                "chi2_dof": res["fit"]["chi_square_per_dof"],
                "cds": {k: (v["value"], v.get("std")) for k, v in res["parameters"].items()
                        if k.startswith("CdS")}}
    return stages


def describe(label: str, stages: dict) -> str:
    """A block of text per run."""
    lines = [f"{label}:"]
    for name, st in stages.items():
        lines.append(f"  {name}: {st['wall_s']:.1f} s, peak {st['peak_mb']:.0f} MB, exit "
                     f"{'stopped' if st['exit'] is None else st['exit']}")
        if name == "reconstruct":
            grid = next((s.strip() for s in st["stdout"] if "shooting grid" in s), "")
            size = next((s.strip() for s in st["stdout"] if s.startswith("solving:")), "")
            lines += [f"    {grid}", f"    {size}",
                      f"    {len(st['progress'])} progress lines on the piped stderr"
                      + (f", the last: {st['progress'][-1].strip()}" if st["progress"] else "")]
            if "fit" in st:
                fit = st["fit"]
                lines.append(f"    {fit['status']}, {fit['iterations']} iterations, chi2/dof "
                             f"{fit['chi2_dof']:.3f}; " + ", ".join(
                                 f"{k} {v:.4f} +- {s or float('nan'):.4f}"
                                 for k, (v, s) in fit["cds"].items())
                             + " (flown: " + ", ".join(f"{k} {v:g}" for k, v in CDS_TRUE.items())
                             + " m^2)")
            elif st["stderr_tail"]:
                lines.append(f"    stderr: {st['stderr_tail'][-1]}")
    return "\n".join(lines)


def total(stages: dict) -> tuple[float, float, bool]:
    """Import plus reconstruction: wall time (s), the larger peak (MB), and whether both
    finished within the timeout."""
    return (sum(s["wall_s"] for s in stages.values()),
            max(s["peak_mb"] for s in stages.values()),
            all(s["exit"] is not None for s in stages.values()))


def main() -> None:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the log's sensor noise")
    parser.add_argument("--cases", default=",".join(CASES),
                        help="channel mixes, comma-separated, each channels joined by + "
                             f"(of {', '.join(CHANNELS)}; baro in every one)")
    parser.add_argument("--baseline", default=BASELINE, help="the revision to compare with")
    parser.add_argument("--no-baseline", action="store_true", help="time this tree only")
    parser.add_argument("--repeat", type=int, default=2,
                        help="runs per tree and case with one compile cache (default 2)")
    parser.add_argument("--timeout", type=float, default=600.0,
                        help="stop a stage after this many seconds")
    parser.add_argument("--no-diameter", action="store_true",
                        help="leave the canopies' diameters out of the card")
    args = parser.parse_args()
    cases = [set(c.split("+")) | {"baro"} for c in args.cases.split(",")]
    results: dict = {}
    ratios: dict = {}
    with tempfile.TemporaryDirectory(prefix="cpas-ocp-long-log-") as tmp:
        trees = [("this tree", None)] + ([] if args.no_baseline else
                                         [(f"baseline {args.baseline}", args.baseline)])
        for channels in cases:
            name = "+".join(c for c in CHANNELS if c in channels)
            folder = Path(tmp) / name
            events = write_log(folder, channels, args.seed, not args.no_diameter)
            print(f"== {name}: drogue {events['drogue']:.1f} s, main {events['main']:.1f} s, "
                  f"touchdown {events['landed']:.1f} s (100 Hz, seed {args.seed})", flush=True)
            for label, revision in trees:
                with code_at(revision) as code, tempfile.TemporaryDirectory() as cache:
                    for k in range(args.repeat):
                        run = f"{label}, run {k + 1}"
                        stages = run_case(code, folder, Path(cache),
                                          args.timeout, f"{label}-{k}".replace(" ", "_"))
                        results.setdefault(name, {})[run] = stages
                        print(describe(run, stages), flush=True)
                        if not total(stages)[2]:
                            break  # stopped: a second run would only be stopped again
            if args.no_baseline:
                continue
            for k in range(args.repeat):
                this = results[name].get(f"this tree, run {k + 1}")
                base = results[name].get(f"baseline {args.baseline}, run {k + 1}") \
                    or results[name].get(f"baseline {args.baseline}, run 1")
                if this is None or base is None:
                    continue
                (t_new, m_new, _), (t_old, m_old, done) = total(this), total(base)
                bound = "" if done else " > (the baseline was stopped)"
                ratios.setdefault(name, {})[f"run {k + 1}"] = {
                    "time": harness.ratio(t_old, t_new), "peak": harness.ratio(m_old, m_new),
                    "baseline_finished": done}
                print(f"  baseline / this tree, run {k + 1}: time{bound} "
                      f"{harness.ratio_text(t_old, t_new)} ({t_old:.0f} s / {t_new:.0f} s), "
                      f"peak {harness.ratio_text(m_old, m_new)} ({m_old:.0f} MB / "
                      f"{m_new:.0f} MB)", flush=True)
    plain = {case: {run: {stage: {k: v for k, v in st.items() if k not in ("stdout",)}
                          for stage, st in stages.items()}
                    for run, stages in runs.items()} for case, runs in results.items()}
    fits = [{"case": case, "run": run, "import_s": stages["import"]["wall_s"],
             "reconstruct_s": stages.get("reconstruct", {}).get("wall_s"),
             "peak_mb": total(stages)[1], "exit": stages.get("reconstruct", {}).get("exit"),
             **fit_row(stages.get("reconstruct", {}).get("fit"))}
            for case, runs in plain.items() for run, stages in runs.items()]
    harness.report("long_log", baseline=None if args.no_baseline else args.baseline,
                   diameter=not args.no_diameter, fits=fits, runs=plain,
                   baseline_over_tree=ratios)


def fit_row(fit: dict | None) -> dict:
    """A reconstruction's solver status, iterations, chi-square/dof and drag areas as one
    table row's figures (empty where it wrote no result)."""
    if fit is None:
        return {}
    return {"status": fit["status"], "iterations": fit["iterations"],
            "chi2_dof": fit["chi2_dof"],
            "drag_areas_m2": harness.estimates_text((k, v, s) for k, (v, s) in fit["cds"].items())}


if __name__ == "__main__":
    main()
