"""The suite's shared fixtures (simulated test folders and their fits), for the studies."""

from tests.conftest import (  # noqa: F401
    drogue_fit,
    drogue_folder,
    problem_fit,
    problem_folder,
    pytest_collection_modifyitems,
)
