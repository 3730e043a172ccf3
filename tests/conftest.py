import numpy as np
import pytest

import uavtrack


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture
def short():
    """The default scenario, shortened for tests."""
    return uavtrack.Scenario(steps=60)
