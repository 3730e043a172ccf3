"""Trust over a real network: a stranger on the world's endpoint, an impostor holding a
member's key file, TLS files a peer would refuse. The programs are OS processes over
Zenoh on loopback; the stranger is a Zenoh session of this process that holds no key."""

import subprocess
import sys
import threading

import numpy as np
import pytest

import uavtrack
from uavtrack.agents import run_swarm
from uavtrack.testing import assert_same_trace

from .processes import wait_until
from .test_agents_faults import make_certificates, tls_options

pytestmark = pytest.mark.integration  # the agent form against real deadlines

pytest.importorskip("zenoh")
pytest.importorskip("cryptography")


class Stranger:
    """A party on the world's endpoint without a key of the run. It hears the world's
    Hello (answered to any join request) and so the run id; once `go` is set it holds
    every liveliness token of the run (`squat`) or makes and drops them one after the
    other, each for 0.1 s over the round (`flap`), and sends a forged Ready and presence
    in every program's name, sealed with keys of its own, until `stop` is set."""

    def __init__(self, endpoint: str, programs: int, mode: str, options=None) -> None:
        self.endpoint, self.programs, self.mode, self.options = endpoint, programs, mode, options
        self.go, self.stop, self.started = threading.Event(), threading.Event(), threading.Event()
        self.learnt: set[str] = set()
        self.run: str | None = None
        self.rounds = 0
        self.thread = threading.Thread(target=self._act, daemon=True)
        self.error: BaseException | None = None

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop.set()
        self.go.set()
        self.thread.join(60)

    def _act(self) -> None:
        from uavtrack.agents.transport import ZenohTransport

        try:
            session = ZenohTransport([], [self.endpoint], self.options)
        except BaseException as exc:  # reported by the test
            self.error = exc
            self.started.set()
            return
        try:
            session.subscribe("uavtrack/*/hello", lambda k, _: self.learnt.add(k.split("/")[1]))
            self.go.wait()
            if not self.stop.is_set():
                self._attack(session)
        except BaseException as exc:
            self.error = exc
        finally:
            self.started.set()
            session.close()

    def _forged(self, run: str) -> list[tuple[str, bytes]]:
        from uavtrack.agents.agent import part
        from uavtrack.agents.messages import VERSION, Radio, Ready, encode
        from uavtrack.agents.security import WORLD, Gate, Keyring
        from uavtrack.agents.transport import inbox_key

        n = self.programs
        ring = Keyring(run, n)  # keys of its own: the right run, no member's
        out = []
        for p in range(n):
            gate = Gate(run=run, me=p, programs=n, credential=ring.credential(p))
            gate.learn(ring.public())
            out.append((inbox_key(run, WORLD), gate.seal(WORLD, encode(Ready(VERSION, run, p)))))
            heard = part("presence", 0, {"heard": np.ones(n, dtype=bool)})
            body = encode(Radio(version=VERSION, run=run, k=-1, sender=p, parts=[heard]))
            out += [(inbox_key(run, q), gate.seal(q, body)) for q in range(n) if q != p]
        return out

    def _attack(self, session) -> None:
        run = self.run
        tokens = [f"uavtrack/{run}/alive/{x}" for x in [*range(self.programs), "world"]]
        forged = self._forged(run)
        liveliness = session.session.liveliness()
        held = [liveliness.declare_token(t) for t in tokens] if self.mode == "squat" else []
        self.started.set()
        while not self.stop.is_set():
            for key, payload in forged:
                session.publish(key, payload)
            if self.mode == "flap":
                for token in tokens:
                    declared = liveliness.declare_token(token)
                    self.stop.wait(0.1 / len(tokens))
                    declared.undeclare()
            else:
                self.stop.wait(0.1)
            self.rounds += 1
        for token in held:
            token.undeclare()


@pytest.mark.parametrize(
    "mode,when,method",
    [
        ("squat", "start", "distributed"),
        ("flap", "start", "distributed"),
        ("squat", "mid-run", "distributed"),
        ("flap", "mid-run", "distributed"),
        ("flap", "start", "centralized"),
    ],
)
def test_a_stranger_making_or_dropping_tokens_neither_stops_nor_changes_a_run(mode, when, method):
    # the stranger holds no key: its tokens, whenever they come and go, take no program's
    # number and lose no program; the run starts and ends as the simulator's
    scenario = uavtrack.Scenario(steps=15)
    programs = scenario.n_uavs + int(method == "centralized")
    holder = {}

    def announce(run, endpoint, written):  # before the programs start
        holder["stranger"] = stranger = Stranger(endpoint, programs, mode).__enter__()
        stranger.run = run
        if when == "start":  # its tokens come before any program's
            stranger.go.set()
            assert stranger.started.wait(120) and stranger.error is None, stranger.error

    def progress(k):
        if when == "mid-run" and k == 5:
            holder["stranger"].go.set()
            holder["stranger"].started.wait(120)

    try:
        swarm = run_swarm(
            scenario, method, seed=2, transport="zenoh", announce=announce, progress=progress
        )
    finally:
        if "stranger" in holder:
            holder["stranger"].__exit__()
    stranger = holder["stranger"]
    assert stranger.error is None and stranger.rounds >= 1
    assert stranger.learnt == {swarm.run}  # the run id is there for anyone to hear
    assert swarm.traffic.lost == {} and swarm.traffic.failed == {}
    assert_same_trace(swarm.result.trace, uavtrack.simulate(scenario, method, seed=2).trace)
    assert swarm.traffic.drops.get("not authentic", 0) >= 1  # its Ready, at least


@pytest.mark.slow  # 34 s of TLS sessions and deadlines: kept out of CI's 15 minutes
def test_an_impostor_holding_a_members_key_file_with_another_secret_takes_no_place(tmp_path):
    # over TLS, with --no-spawn: a program started with a copy of program 0's key file
    # whose secret is not 0's is told that its key is not 0's (exit 2); a stranger
    # holding the swarm's TLS certificate but no key makes every token of the run and
    # sends a Ready in every name. Neither takes a place: the real programs join, and
    # the run is the simulator's. Once the real program 0 has joined (the world's Hello
    # names it), a second program with its key is told that 0 runs already (exit 2)
    import dataclasses

    from uavtrack.agents.security import Credential
    from uavtrack.agents.transport import ZenohTransport

    files = make_certificates(tmp_path / "tls")
    scenario = uavtrack.Scenario(steps=8)
    joined, done = {}, {}

    def world():
        try:
            done["swarm"] = run_swarm(
                scenario,
                "distributed",
                seed=5,
                transport="zenoh",
                spawn=False,
                keys=tmp_path,
                zenoh=tls_options(files),
                announce=lambda run, endpoint, written: joined.update(
                    run=run, endpoint=endpoint, keys=written
                ),
                startup=120,  # the programs start once the impostor has gone
            )
        except BaseException as exc:
            done["error"] = exc

    thread = threading.Thread(target=world)
    thread.start()
    tls = ["--tls-ca", str(files["ca"]), "--tls-cert", str(files["cert"])]
    tls += ["--tls-key", str(files["key"])]
    processes, probe, stranger = [], None, None
    try:
        assert wait_until(lambda: "keys" in joined or "error" in done), done
        run, endpoint = joined["run"], joined["endpoint"]
        real = Credential.read(joined["keys"][0])
        forged = tmp_path / "impostor.key"
        dataclasses.replace(real, secret=bytes(range(32))).write(forged)
        agent = [sys.executable, "-m", "uavtrack.cli", "agent", "--connect", endpoint, *tls]

        def start(key):
            process = subprocess.Popen(
                agent + ["--key", str(key)], stdout=subprocess.PIPE, stderr=subprocess.PIPE
            )
            processes.append(process)
            return process

        probe = ZenohTransport([], [endpoint], tls_options(files))
        impostor = start(forged)
        # it leaves, or it holds program 0's token (as it did when a token took a number)
        assert wait_until(
            lambda: impostor.poll() is not None or probe.alive(f"uavtrack/{run}/alive/0"), 300
        )
        stranger = Stranger(endpoint, 5, "squat", tls_options(files)).__enter__()
        stranger.run = run
        stranger.go.set()
        assert stranger.started.wait(120) and stranger.error is None, stranger.error
        hellos = []
        probe.subscribe(f"uavtrack/{run}/hello", lambda _, payload: hellos.append(payload))
        members = [start(key) for key in joined["keys"][:2]]
        assert wait_until(lambda: any(0 in members_of(h, run) for h in hellos[-5:]), 300)
        second = start(joined["keys"][0])
        _, twice = second.communicate(timeout=300)
        members += [start(key) for key in joined["keys"][2:]]
        thread.join(600)
        outputs = [p.communicate(timeout=120) for p in members]
        _, said = impostor.communicate(timeout=120)
    finally:
        if stranger is not None:
            stranger.__exit__()
        if probe is not None:
            probe.close()
        for process in processes:
            if process.poll() is None:
                process.kill()
                process.communicate()
        thread.join(60)
    assert "error" not in done, done.get("error")
    for process, (out, err) in zip(members, outputs, strict=True):
        assert process.returncode == 0, err.decode()
        assert b"ran 8 of 8 cycles" in out
    assert second.returncode == 2 and "program 0 of run" in twice.decode()
    assert "is already running" in twice.decode()
    assert impostor.returncode == 2 and said.decode().count("\n") == 1
    assert f"--key: {forged} does not hold program 0's key" in said.decode()
    swarm = done["swarm"]
    assert swarm.traffic.lost == {} and stranger.rounds >= 1
    assert_same_trace(swarm.result.trace, uavtrack.simulate(scenario, "distributed", seed=5).trace)


def members_of(payload: bytes, run: str) -> list[int]:
    """The members a world's Hello names (none if the payload is not one)."""
    import msgspec

    from uavtrack.agents.messages import Hello, decode
    from uavtrack.agents.security import Envelope

    try:
        message = decode(msgspec.msgpack.decode(payload, type=Envelope).body, run)
    except msgspec.DecodeError:
        return []
    return list(message.members) if isinstance(message, Hello) else []


# ------------------------------------------------------------------ TLS files


def run_cli(capsys, *args):
    from uavtrack import cli

    code = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def tls_args(files):
    return ["--tls-ca", files["ca"], "--tls-cert", files["cert"], "--tls-key", files["key"]]


def test_tls_files_with_a_clear_endpoint_are_refused_in_one_line(tmp_path, capsys):
    # the files secure tls/ links only: with a tcp/ endpoint the swarm would run in clear
    from uavtrack.errors import UsageError

    files = make_certificates(tmp_path / "tls")
    fix = "would run in clear text: use tls/127.0.0.1:"
    for args in (
        ["swarm", "--transport", "zenoh", "--listen", "tcp/127.0.0.1:0", "--set", "steps=3"],
        ["swarm", "--transport", "zenoh", "--connect", "tcp/127.0.0.1:1", "--set", "steps=3"],
        ["agent", "--run", "0123456789ab", "--uav", "0", "--connect", "tcp/127.0.0.1:1"],
    ):
        code, out, err = run_cli(capsys, *args, *tls_args(files))
        assert code == 2 and fix in err and err.count("\n") == 1 and out == "", (args, err)
    with pytest.raises(UsageError, match=fix):  # and from Python
        run_swarm(
            uavtrack.Scenario(steps=3),
            transport="zenoh",
            listen="tcp/127.0.0.1:0",
            zenoh=tls_options(files),
        )


def refused_files(tmp_path, case):
    """TLS files that peers refuse, the option at fault and what is said of it."""
    if case == "expired":
        return make_certificates(tmp_path, host_days=(-30, -1)), "--tls-cert", "expired on"
    if case == "not yet valid":
        found = make_certificates(tmp_path, host_days=(1, 30))
        return found, "--tls-cert", "is not valid before"
    if case == "expired CA":
        return make_certificates(tmp_path, ca_days=(-30, -1)), "--tls-ca", "expired on"
    if case == "another CA's":  # a CA of the same name, another key, signed it
        other = make_certificates(tmp_path / "other")
        found = make_certificates(tmp_path, signer=other)
        return found, "--tls-cert", "is not signed by the CA of --tls-ca"
    if case == "another certificate's key":
        found = make_certificates(tmp_path)
        found["key"] = make_certificates(tmp_path / "other")["key"]
        return found, "--tls-key", "is not the key of --tls-cert"
    found = make_certificates(tmp_path)
    found["key"].chmod(0o644)
    return found, "--tls-key", "permissions 0644 are too open"


CASES = [
    "expired",
    "not yet valid",
    "expired CA",
    "another CA's",
    "another certificate's key",
    "key others can read",
]


@pytest.mark.parametrize("case", CASES)
def test_a_tls_file_peers_would_refuse_is_named_by_the_program_holding_it(tmp_path, capsys, case):
    files, option, reason = refused_files(tmp_path / "tls", case)
    at_fault = files[{"--tls-ca": "ca", "--tls-cert": "cert", "--tls-key": "key"}[option]]
    code, out, err = run_cli(
        capsys,
        *["agent", "--run", "0123456789ab", "--uav", "0", "--connect", "tls/127.0.0.1:1"],
        *tls_args(files),
    )
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert f"{option}: {at_fault}" in err and reason in err


@pytest.mark.parametrize("case", ["expired", "another CA's"])
def test_the_world_names_its_own_refused_certificate_at_once(tmp_path, capsys, case):
    # before Zenoh starts, and before any program: not as timeouts of every program
    files, option, reason = refused_files(tmp_path / "tls", case)
    code, out, err = run_cli(
        capsys, "swarm", "--transport", "zenoh", "--set", "steps=3", *tls_args(files)
    )
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert f"{option}: {files['cert']}" in err and reason in err
