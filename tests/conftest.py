import signal

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


@pytest.fixture(scope="session", autouse=True)
def ctrl_c_reaches_children():
    """A shell that starts the tests in the background (``pytest &``) makes them ignore
    SIGINT, and the commands they start would inherit that and never see a Ctrl-C;
    handling it here gives them the default, as from a terminal."""
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
