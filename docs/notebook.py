# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # cpas-ocp in a notebook
#
# This notebook is a plain Python file in jupytext's percent format: run it with
# `python docs/notebook.py`, or open it in Jupyter with jupytext installed.
# `tests/api/test_notebook.py` runs it as part of the suite. It goes through the loop:
#
# 1. reconstruct a test;
# 2. see where the model fits worst;
# 3. diagnose what is missing;
# 4. add it and watch the error fall.
#
# The data are a simulated FBCP phase flown with canopy added mass, which the
# baseline model leaves out.

# %%
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # figures to files; drop this line in Jupyter
import matplotlib.pyplot as plt

import cpas_ocp as co

work = Path(tempfile.mkdtemp(prefix="cpas-notebook-"))
truth = {"added_mass_factor[fbcp1]": 1.4, "added_mass_factor[fbcp2]": 1.4}
test = co.simulate("fbcp", work / "fbcp", seed=1,
                   effects=[*co.baseline_effects(), co.effect("added_mass")], truth=truth)

# %% [markdown]
# ## 1. Reconstruct with the baseline model
#
# The test folder's own model is the baseline: inflation, forebody drag,
# rigid risers, drag and load-cell scales, and the three sensors. Every value is
# SI, and every parameter carries its 1σ.

# %%
rec = co.reconstruct(test)
print(repr(rec))  # in Jupyter, `rec` alone on a cell's last line shows its parameter table
print(rec.summary())

# %% [markdown]
# ## 2. Where the model fits worst

# %%
print(rec.worst)
axes = rec.plot("riser_fbcp1")  # tension over its residuals, the phase windows shaded
axes[0].figure.savefig(work / "riser_fbcp1.png", dpi=80)
plt.close(axes[0].figure)

# %% [markdown]
# ## 3. What is missing
#
# The diagnosis runs a score test on every library effect the model leaves out.
# It confirms the significant ones with a refit and a likelihood-ratio test.

# %%
diag = rec.diagnose()
print(diag.verdict())

# %% [markdown]
# ## 4. Add it and watch the error fall
#
# The fit's own model with the effect added (a model file with the effect in its
# list does the same); the comparison fits it from the baseline fit, so the two
# models are nested and the likelihood ratio is a test.

# %%
comparison = rec.compare(rec.spec_with("added_mass"), labels=("baseline", "added mass"))
print(co.summary(comparison))
