"""The suite's shared fixtures (simulated test folders and their fits), for the studies."""

from tests.campaign.test_campaign import tests_root  # noqa: F401 (the dask study's tests)
from tests.campaign.test_monte_carlo_cli import study  # noqa: F401 (and its Monte Carlo run)
from tests.conftest import (  # noqa: F401
    drogue_fit,
    drogue_folder,
    problem_fit,
    problem_folder,
    pytest_collection_modifyitems,
)
