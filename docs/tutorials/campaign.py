# %% [markdown]
# # A campaign, its populations and Monte Carlo cases
#
# Four tests of a pair of Forward Bay Cover Parachutes (the built-in `fbcp`
# test) reconstructed in parallel, the canopy type's population fitted from
# their estimates with each test's own covariance, and Monte Carlo cases drawn
# from the fitted population. The canopies' positions in the pair (fbcp1,
# fbcp2) enter as a covariate by default.

# %%
import tempfile
from pathlib import Path

import cpas_ocp as co

work = Path(tempfile.mkdtemp(prefix="cpas-campaign-"))
for i in range(4):  # four tests, each with its own sensor noise
    co.simulate("fbcp", work / "tests" / f"test{i}", seed=100 + i)
campaign = co.reconstruct_campaign(work / "tests", work / "campaign", workers=2)
print(campaign.summary())

# %% [markdown]
# ## The populations
#
# Per canopy type and stage and per parameter: the population median and the
# between-test spread τ (in log space), each with its 95 % interval, and the
# share of the spread each covariate explains. Four tests say little about τ:
# its interval is wide, and says so.

# %%
population = co.population(work / "campaign")
population.report(work / "population")
print(population.summary())

# %% [markdown]
# ## Monte Carlo cases
#
# Cases drawn from each fitted population, inside the caps and the grown hull
# of the point estimates, at the configuration named (here the second
# position). `co.monte_carlo(test, cases, out)` flies them through a
# reconstruction for peak loads; `co.design` can average a planned test's σ
# over them.

# %%
cases = co.dispersions(work / "campaign", work / "cases", cases=200, seed=1,
                       from_population=True, at={"position": "fbcp2"})
print("\n".join(cases.notes))
print(sorted(p.name for p in (work / "cases").glob("cases_*.parquet")))
