"""The program launcher of `uavtrack swarm`: it forks programs that run as started ones,
reports how each ended, signals only its own children, and takes them with it when it
goes, whichever way it goes."""

import os
import signal
import subprocess
import sys
import tempfile
from dataclasses import asdict

import pytest

import uavtrack
from uavtrack.agents import run_swarm
from uavtrack.agents.launcher import LAUNCHER, NAME, Launcher
from uavtrack.agents.swarm import free_port
from uavtrack.agents.transport import ZenohOptions
from uavtrack.errors import RunError

from .processes import alive, children_of, descendants_of, programs_of, wait_until

pytest.importorskip("zenoh")

pytestmark = pytest.mark.integration  # it starts processes


def spec(me, connect, **zenoh):
    """A program's spec, as `uavtrack swarm` hands it over."""
    return {
        "run": "0123456789ab",
        "program": me,
        "connect": connect,
        "zenoh": asdict(ZenohOptions(**zenoh)),
        "credential": None,
        "parent": os.getpid(),
        "ros2": None,
    }


def printed(log):
    log.seek(0)
    return log.read().decode()


@pytest.fixture
def launcher():
    made = Launcher()
    yield made
    made.close(grace=10.0)
    assert made.process.returncode == 0


@pytest.fixture
def waiting():
    """An endpoint with a Zenoh peer and no world: a program joins it and waits there."""
    import zenoh

    port = free_port()
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("listen/endpoints", f'["tcp/127.0.0.1:{port}"]')
    config.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(config)
    yield f"tcp/127.0.0.1:{port}"
    session.close()


def test_a_forked_program_ends_as_a_started_one_with_its_words_and_code(launcher, tmp_path):
    missing = str(tmp_path / "no-ca.pem")
    with tempfile.TemporaryFile() as log:
        program = launcher.start(3, spec(3, ["tls/127.0.0.1:1"], tls_ca=missing), log)
        assert program.wait(timeout=60) == 2  # the same code as `python -m uavtrack.agents`
        assert printed(log) == "program 3: TLS needs all three of tls_ca, tls_cert and tls_key\n"
    assert program.pid not in children_of(launcher.process.pid)  # reaped


def test_the_launcher_names_signals_and_reaps_its_programs(launcher, waiting):
    with tempfile.TemporaryFile() as log:
        programs = [launcher.start(me, spec(me, [waiting]), log) for me in (0, 7)]
        pids = [p.pid for p in programs]
        assert sorted(children_of(launcher.process.pid)) == sorted(pids)
        for me, pid in zip((0, 7), pids, strict=True):
            assert open(f"/proc/{pid}/comm", "rb").read().strip() == NAME % me
        assert programs[0].poll() is None
        programs[0].send_signal(signal.SIGTERM)
        assert programs[0].wait(timeout=60) == -signal.SIGTERM
        assert programs[1].poll() is None  # the other one still waits for its world
        programs[1].kill()
        assert programs[1].wait(timeout=60) == -signal.SIGKILL
        assert not any(alive(pid) for pid in pids)


def test_the_launcher_signals_no_process_but_its_own(launcher):
    stranger = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
    try:
        launcher.signal(stranger.pid, signal.SIGKILL)  # not its child: ignored
        launcher.signal(stranger.pid, signal.SIGKILL)
        with tempfile.TemporaryFile() as log:  # a round trip: the requests were read
            done = launcher.start(1, spec(1, ["tls/127.0.0.1:1"], tls_ca="/nonexistent"), log)
            assert done.wait(timeout=60) == 2
        assert stranger.poll() is None
    finally:
        stranger.kill()
        stranger.wait()


def test_closing_the_launcher_stops_what_still_runs(waiting):
    made = Launcher()
    with tempfile.TemporaryFile() as log:
        program = made.start(2, spec(2, [waiting]), log)
        made.close(grace=30.0)
        assert program.wait(timeout=60) == -signal.SIGTERM
    assert made.process.returncode == 0 and not alive(program.pid)


def test_a_killed_launcher_takes_its_programs_and_says_so(waiting):
    made = Launcher()
    try:
        with tempfile.TemporaryFile() as log:
            program = made.start(4, spec(4, [waiting]), log)
            os.kill(made.process.pid, signal.SIGKILL)
            # its end reaches us as the socket closing; the program's parent-death signal
            assert program.wait(timeout=60) == -signal.SIGKILL
            assert wait_until(lambda: not alive(program.pid), limit=30)
            with pytest.raises(RunError, match=r"launcher ended \(killed by SIGKILL\)"):
                made.start(5, spec(5, [waiting]), log)
    finally:
        made.close()


def test_a_swarm_whose_launcher_is_killed_ends_at_once_with_one_line():
    # every UAV program ends with the launcher: the run cannot go on, and says why
    seen = {}

    def progress(k):
        if k == 3:
            below = descendants_of(os.getpid())
            seen["programs"] = set(programs_of(os.getpid()).values())
            names = {pid: open(f"/proc/{pid}/comm", "rb").read().strip() for pid in below}
            (launcher,) = [pid for pid, name in names.items() if name == LAUNCHER]
            seen["launcher"] = launcher
            os.kill(launcher, signal.SIGKILL)

    scenario = uavtrack.Scenario().model_copy(update={"steps": 400})
    with pytest.raises(RunError) as caught:
        run_swarm(scenario, transport="zenoh", seed=1, progress=progress)
    text = str(caught.value)
    assert text.startswith("the program launcher ended (killed by SIGKILL) at step ")
    assert "\n" not in text and 3 <= int(text.split("at step ")[1].split(",")[0]) < 20
    assert len(seen["programs"]) == 5
    assert wait_until(lambda: not any(alive(p) for p in seen["programs"]), limit=30)


def test_garbage_on_the_launchers_socket_ends_it_and_says_so(waiting, monkeypatch):
    """A report that is not one: the reader does not die with the launcher still
    believed; the launcher is killed, by its pid, with its programs, and a start or the
    swarm's next cycle ends with one line naming it."""
    made_reader = Launcher._receive
    reports = []

    def receive(self):
        if reports:  # after the first report (a start), garbage
            return b"\xff not a report"
        reports.append(made_reader(self))
        return reports[0]

    monkeypatch.setattr(Launcher, "_receive", receive)
    made = Launcher()
    try:
        with tempfile.TemporaryFile() as log:
            program = made.start(4, spec(4, [waiting]), log)  # its report, then the garbage
            assert program.wait(timeout=60) == -signal.SIGKILL  # gone with its launcher
            assert made.gone and made.process.wait(timeout=30) == -signal.SIGKILL
            with pytest.raises(RunError, match=r"launcher sent a report that is not one"):
                made.start(5, spec(5, [waiting]), log)
    finally:
        made.close()
