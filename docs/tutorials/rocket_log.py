# %% [markdown]
# # A rocket log
#
# A flight computer's log, as it came off the recorder, imported under a flight card
# into a test folder, then reconstructed: the drag area of each canopy, fitted to the
# altimeter to its noise, or a plain sentence where a canopy did not open.
# Run it with `python docs/tutorials/rocket_log.py`; the suite runs it as printed.
#
# So that this page runs without a log of your own, `example_log` writes what an
# Altus Metrum flight computer logs of a known flight (a 16.3 kg rocket, a 24 in
# drogue at apogee, a 72 in main at 300 m) and the flight card a flyer writes for it
# from [the flight-card page](../flight-card.md). With your own, start from your
# recorder's file and your card.

# %%
import json
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # figures to files; drop this line in Jupyter

import cpas_ocp as co
from cpas_ocp.io.example_flight import example_log

work = Path(tempfile.mkdtemp(prefix="cpas-rocket-log-"))
flown = example_log(work / "flight", seed=1)  # flight.csv and card.json
print(json.dumps(json.loads((flown / "card.json").read_text())["parachutes"][0], indent=1))

# %% [markdown]
# ## The import
#
# One call (or `cpas-ocp import flight.csv --card card.json --out test`) reads the
# recorder's format, finds the flight's events from its states or its sensors, drops
# what is not a measurement (repeated rows, the ejection charges' pressure pulses),
# estimates each sensor's noise from the log itself, and says for each canopy whether
# it opened, from the descent rates before and after its charge.

# %%
imported = co.import_log(flown / "flight.csv", flown / "card.json", work / "test")
print(co.summary(imported))

# %% [markdown]
# ## The reconstruction
#
# The test folder reconstructs like any other: one NLP over the descent, each
# canopy's drag area with its σ, and whether the fit is a result (χ² within the
# noise, no bound pressed, every drag area determined).

# %%
rec = co.reconstruct(work / "test")
print(rec.summary())
assert rec.is_result, rec.problems

# %% [markdown]
# ## A recovery that failed
#
# The same rocket, whose main's charge fires at 300 m and whose canopy never
# inflates. The import says so in a sentence, and the fit holds the main closed
# rather than fitting it a drag area the descent never showed.

# %%
failed = example_log(work / "failed", seed=2, main_opens=False)
imported = co.import_log(failed / "flight.csv", failed / "card.json", work / "failed-test")
print(imported.deployments["main"]["sentence"])
