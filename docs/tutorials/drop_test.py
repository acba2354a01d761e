# %% [markdown]
# # A drop test, end to end
#
# A built-in Drogue test (two Drogues through three stages, 20 s of GPS, IMU and
# riser load cells) simulated with sensor noise, reduced offline for the initial
# guess, reconstructed in one NLP, judged, reported, and asked a what-if question.
# Run it with `python docs/tutorials/drop_test.py`; the suite runs it as printed.

# %%
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # figures to files; drop this line in Jupyter

import cpas_ocp as co

work = Path(tempfile.mkdtemp(prefix="cpas-drop-test-"))
test = co.simulate("drogue", work / "test", seed=1)  # or co.load_test("my-test-folder")

# %% [markdown]
# ## The offline reduction
#
# The legacy process's reduction (drag area from the load cells and the
# trajectory, paper Eqs. 2-3) gives the estimator its initial guess: the
# estimator never sees the simulation's truth.

# %%
guess = co.reduce(test, work / "reduction")
print(guess.summary())

# %% [markdown]
# ## The reconstruction
#
# One multiple-shooting NLP over the whole phase: inflation parameters, scale
# factors and start times together. Each value is printed with its σ, both
# rounded to the σ's two significant digits. A fit that is not a result
# (a bound pressed, χ² beyond the noise, a drag area undetermined) says why.

# %%
rec = co.reconstruct(test)
print(rec.summary())
assert rec.is_result, rec.problems

# %% [markdown]
# `rec.parameters` is the same table in SI with full precision, for further work;
# `rec.worst` names the window where the model fits worst.

# %%
print(rec.parameters.head())
print(rec.worst)

# %% [markdown]
# ## Model against measurement
#
# Each sensor's model over its measurement, with normalised residuals below;
# `rec.report(...)` writes every figure, `report.md` and `report.html`.

# %%
axes = rec.plot("riser_drogue1")
axes[0].figure.savefig(work / "riser_drogue1.png")
report = rec.report(work / "report")
print(sorted(p.name for p in report.iterdir())[:6])

# %% [markdown]
# ## What if
#
# Hold a parameter at a value and re-solve: the χ² it costs and whether the
# data allow it (a likelihood-ratio test).

# %%
held = rec.what_if("Ck[drogue1,stage1] == 1.0")
print(f"holding Ck at 1.0 costs Δχ² {held.delta_chi_square:.1f} (p = {held.p_value:.2g})")
