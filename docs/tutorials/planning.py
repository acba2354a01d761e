# %% [markdown]
# # Planning the next test
#
# Before a drop: the σ each parameter will have under candidate instrumentations
# of a planned test, predicted from the Fisher information of the estimator
# that will reconstruct it, and which single sensor change buys the most. The
# plan file's fields are in [the formats](../formats/test_plan.md).
#
# The planned test is the built-in `fbcp` phase (two canopies, GPS, IMU, a load
# cell on each riser); the changes to rank are a faster GPS, a quieter IMU, a
# better load cell and a camera timing each canopy's full open.

# %%
import json
import tempfile
from pathlib import Path

import cpas_ocp as co

work = Path(tempfile.mkdtemp(prefix="cpas-planning-"))
plan = {
    "format": "cpas-ocp/test-plan/1",
    "problem": "fbcp",
    "interest": ["Ck[fbcp1,stage1]", "n_p[fbcp1,stage1]"],
    "changes": [
        {"label": "GPS at 50 Hz", "sensor": {"name": "gps", "rate_hz": 50}},
        {"label": "IMU at 0.005 g",
         "sensor": {"name": "imu", "sigma": {"load_factor": {"value": 0.005, "unit": "g"}}}},
        {"label": "fbcp1 load cell at 1 %",
         "sensor": {"name": "riser_fbcp1", "sigma_relative": 0.01}},
        {"label": "full open timed to 5 ms",
         "event_sigma": {"full_open": {"value": 5, "unit": "ms"}}},
    ],
}
(work / "plan.json").write_text(json.dumps(plan, indent=1))
design = co.design(work / "plan.json", out=work / "design")

# %% [markdown]
# Every candidate's predicted σ; a parameter the plan cannot determine is
# named with the combination it is lost in, not given a number.

# %%
print(design.sigma_table().round(4))

# %% [markdown]
# The single changes ranked by the share of σ they remove from the parameters
# the plan names, best first.

# %%
for change in design.ranking[:5]:
    print(f"{change.change.label:40s} {100 * change.score:+6.1f} %")
