"""The test loops, seen from a test suite run with this suite's own conftest: the fast loop's
wall (`tests.isolation`) fails a test not marked integration that starts a process or
opens an endpoint, saying what to do, before anything starts, and lets one marked
integration; slow tests run only when -m names them."""

import pytest

pytest_plugins = ["pytester"]

UNMARKED = """
import multiprocessing
import socket
import subprocess
import sys

import pytest


def test_subprocess():
    subprocess.run([sys.executable, "-c", "pass"])


def test_process():
    multiprocessing.get_context("spawn").Process(target=print).start()


def test_pool_worker():
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(1) as pool:
        pool.submit(print).result()


def test_connect():
    with socket.socket() as s:
        s.connect(("127.0.0.1", 9))


def test_swallowed():
    try:
        subprocess.run(["true"])
    except BaseException:
        pass


@pytest.fixture(scope="module")
def server():
    return subprocess.Popen([sys.executable, "-c", "pass"])


def test_fixture(server):
    pass


def test_unix_socket_pair_is_no_endpoint():
    a, b = socket.socketpair()
    with a, b:
        a.sendall(b"x")
        assert b.recv(1) == b"x"
"""

MARKED = """
import socket
import subprocess
import sys

import pytest


@pytest.mark.integration
def test_may():
    assert subprocess.run([sys.executable, "-c", "pass"]).returncode == 0
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
"""


@pytest.fixture
def nested(pytester, monkeypatch):
    """A test suite of its own, with this suite's conftest and markers."""
    monkeypatch.setenv("PYTEST_DISABLE_PLUGIN_AUTOLOAD", "1")  # no installed plugins: quicker
    pytester.makeini("[pytest]\nmarkers =\n    integration: processes\n    slow: long\n")
    return pytester


def run(nested, source, *args):
    nested.makepyfile(test_nested=source)
    return nested.runpytest_inprocess("-p", "tests.conftest", "--strict-markers", "-rfE", *args)


def test_a_test_not_marked_integration_fails_as_it_starts_a_process_or_an_endpoint(nested):
    result = run(nested, UNMARKED)
    result.assert_outcomes(failed=5, errors=1, passed=1)
    out = result.stdout.str()
    for test, what in [
        ("test_subprocess", "starts a process (subprocess)"),
        ("test_process", "starts a process (multiprocessing)"),
        ("test_pool_worker", "starts a process (multiprocessing)"),
        ("test_connect", "opens a network endpoint (socket connect)"),
        ("test_swallowed", "starts a process (subprocess)"),
        ("test_fixture", "starts a process (subprocess)"),
    ]:
        assert f"test_nested.py::{test} {what}, which the fast loop" in out
    assert out.count("mark it @pytest.mark.integration") >= 6


def test_zenoh_and_jsbsim_are_refused_too(nested):
    pytest.importorskip("zenoh")
    pytest.importorskip("jsbsim")
    source = (
        "import jsbsim, zenoh\n\n"
        "def test_zenoh():\n    zenoh.open(zenoh.Config())\n\n"
        "def test_jsbsim():\n    jsbsim.FGFDMExec(None)\n"
    )
    result = run(nested, source)
    result.assert_outcomes(failed=2)
    out = result.stdout.str()
    assert "test_zenoh opens a Zenoh session" in out and "test_jsbsim runs JSBSim" in out


@pytest.mark.integration
def test_a_test_marked_integration_may_start_processes_and_endpoints(nested):
    run(nested, MARKED).assert_outcomes(passed=1)


LOOPS = """
import pytest


def test_maths():
    pass


@pytest.mark.slow
def test_long():
    pass


@pytest.mark.integration
def test_processes():
    pass
"""


@pytest.mark.parametrize(
    "expression, selected",
    [
        ("not integration", {"test_maths"}),
        ("integration", {"test_processes"}),
        ("slow", {"test_long"}),
        ("not slow", {"test_maths", "test_processes"}),
    ],
)
def test_slow_tests_run_only_when_the_expression_names_them(nested, expression, selected):
    # -m on the command line replaces the -m 'not slow' of pyproject's addopts
    result = run(nested, LOOPS, "-m", expression, "-v")
    ran = {
        name
        for name in ("test_maths", "test_long", "test_processes")
        if f"::{name} " in result.stdout.str()
    }
    assert ran == selected
    result.assert_outcomes(passed=len(selected), deselected=3 - len(selected))
