import numpy as np
import pytest

from planner.robot import load_robot


@pytest.fixture(scope="session")
def littledog():
    return load_robot("littledog")


@pytest.fixture
def rng():
    return np.random.default_rng(20261122)
