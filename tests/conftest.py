import platform
import signal

import numpy as np
import pytest

import uavtrack

from . import isolation

# platform learns the processor by running `uname -p`, once per process: asked here,
# outside the wall of `isolation`, so that a library asking on import (h5py) starts no
# process inside whichever test imports it first
platform.processor()


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


@pytest.hookimpl(wrapper=True)
def pytest_runtest_setup(item):
    """Fixtures of any scope a test sets up are inside the wall of `tests.isolation`."""
    with isolation.guard(item):
        return (yield)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item):
    """A test not marked integration fails as soon as it starts a process or an endpoint."""
    with isolation.guard(item):
        return (yield)


def pytest_collection_modifyitems(config, items):
    """Slow tests run only when the -m expression names them: the command line's
    ``-m "not integration"`` replaces the ``-m 'not slow'`` of pyproject's addopts, and
    would otherwise bring the long statistical checks into the fast loop."""
    if "slow" in (config.option.markexpr or ""):
        return
    slow = [item for item in items if item.get_closest_marker("slow")]
    if slow:
        config.hook.pytest_deselected(items=slow)
        items[:] = [item for item in items if not item.get_closest_marker("slow")]
