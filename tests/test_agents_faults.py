"""A lost program never loses the run: UAV and central programs killed or stopped at any
moment, programs joining a run under way, and TLS between the processes.

The programs are real OS processes over Zenoh on loopback; every kill is placed by an
event (the world's progress), never by a sleep, so a loaded machine moves it in time
but not in meaning."""

import json
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

import uavtrack
from uavtrack.agents import run_swarm
from uavtrack.errors import RunError

from .processes import alive, programs_of, wait_until

pytest.importorskip("zenoh")

pytestmark = pytest.mark.integration  # swarms of programs over Zenoh


def program_pids():
    """This process's spawned programs by number."""
    return programs_of(os.getpid())


def swarm_with(scenario, method="distributed", act=None, at=None, between=False, **options):
    """Run a swarm over Zenoh in this process; `act(pids)` runs in its own thread once
    the world has finished `at` cycles (None: once the programs are up, before the first
    cycle), so it lands somewhere in the cycles after; with `between`, in the world's
    own thread between cycle at - 1 and cycle at. Returns the swarm's result (or raises
    what run_swarm raised)."""
    reached = threading.Event()

    def progress(k):
        if between and k == at:
            act(program_pids())
        elif at is not None and k >= at:
            reached.set()

    def act_when_due():
        if at is None:
            wait_until(lambda: len(program_pids()) == len(expected))
        elif not reached.wait(300):
            return
        act(program_pids())

    expected = range(scenario.n_uavs + int(method == "centralized"))
    thread = threading.Thread(target=act_when_due, daemon=True)
    if not between:
        thread.start()
    try:
        return run_swarm(scenario, method, seed=5, transport="zenoh", progress=progress, **options)
    finally:
        if not between:
            thread.join(60)


def kill(i):
    return lambda pids: os.kill(pids[i], signal.SIGKILL)


@pytest.mark.parametrize(
    "at,between",
    [(1, False), (12, False), (23, True)],
    ids=["first-cycles", "mid-run", "last-cycle"],
)
def test_a_killed_uav_program_is_lost_and_the_others_go_on(at, between):
    # unpaced: the kill lands inside one of the first cycles or mid-run, wherever the
    # machine puts it; for the last cycle, placed just before it (landing after it, the
    # program would have sent its last report and nothing would be lost)
    scenario = uavtrack.Scenario(steps=24, comm_range=80.0)
    swarm = swarm_with(scenario, act=kill(2), at=at, between=between, deadline=0.5)
    tr = swarm.result.trace
    assert not swarm.traffic.failed  # no failure of the fault model: a lost program
    lost = swarm.traffic.lost[2]
    assert set(swarm.traffic.lost) == {2} and at <= lost < scenario.steps
    assert lost == at or not between
    assert not tr.alive[lost:, 2].any() and tr.alive[:lost, 2].all()
    assert not tr.observed[lost:, 2].any() and (tr.assignment[lost:, 2] == -1).all()
    assert np.isnan(tr.mean[lost:, 2]).all()
    assert tr.alive[:, [0, 1, 3, 4]].all() and (tr.assignment[:, [0, 1, 3, 4]] >= 0).all()
    assert tr.observed[:, [0, 1, 3, 4]].any()
    result = swarm.result  # every metric masks it, as it masks a failed UAV
    for name in ("ospa", "ospa_best", "gospa", "rmse", "nees", "rmse_best"):
        assert np.isfinite(getattr(result, name)), name


def test_a_program_killed_before_the_first_cycle_stops_the_start_and_says_so(monkeypatch):
    # program 3 is killed as soon as it is forked, and its end reported before the world
    # starts the next one: the kill lands before the first cycle however busy the machine
    from uavtrack.agents import swarm

    start = swarm.Child.start.__func__

    def start_and_kill(cls, me, spec, launcher):
        child = start(cls, me, spec, launcher)
        if me == 3:
            os.kill(child.process.pid, signal.SIGKILL)
            child.process.wait(60)
        return child

    monkeypatch.setattr(swarm.Child, "start", classmethod(start_and_kill))
    scenario = uavtrack.Scenario(steps=10)
    said = r"exited before the run started: program 3 \(exit code -9\)"
    with pytest.raises(RunError, match=said):
        run_swarm(scenario, "distributed", seed=5, transport="zenoh", startup=120)


def test_the_central_node_lost_is_reported_and_the_uavs_fly_on_without_waiting():
    # centralized: the central node is program 5; killed, its UAVs keep their own filters
    # and last targets, and no cycle waits for its download any more
    scenario = uavtrack.Scenario(steps=20)
    deadline = 60.0  # a cycle that waited for the download would take a minute
    swarm = swarm_with(scenario, "centralized", act=kill(5), at=8, between=True, deadline=deadline)
    lost = swarm.traffic.lost
    assert lost == {5: 8}
    tr = swarm.result.trace
    assert tr.alive.all() and (tr.assignment >= 0).all()
    assert max(swarm.traffic.cycle_seconds[lost[5] + 1 :]) < deadline / 2
    # without downloads each UAV keeps its own estimates: they differ between UAVs again
    after = tr.mean[lost[5] + 2 :]
    assert not np.allclose(after[:, 0], after[:, 1])


def test_a_stopped_uav_program_costs_time_not_the_run():
    # SIGSTOP for a few seconds mid-run: its neighbours give up on it round by round,
    # it reports late or is lost; either way the run ends with a whole trace
    scenario = uavtrack.Scenario(steps=30, comm_range=80.0)

    def stop_then_go(pids):
        os.kill(pids[1], signal.SIGSTOP)
        threading.Event().wait(3.0)
        os.kill(pids[1], signal.SIGCONT)

    swarm = swarm_with(scenario, act=stop_then_go, at=5, deadline=0.3)
    tr = swarm.result.trace
    assert tr.alive[:, [0, 2, 3, 4]].all()
    assert set(swarm.traffic.lost) <= {1}
    assert np.isfinite(swarm.result.ospa) and np.isfinite(swarm.result.rmse)


def test_killing_a_program_mid_run_still_exits_0_with_the_trace(tmp_path, capsys, monkeypatch):
    # the command line end to end: exit 0, the trace written, the lost UAV in the JSON
    from contextlib import contextmanager

    from uavtrack import cli
    from uavtrack.cli import swarm as swarm_cli

    @contextmanager
    def steps(scenario, **_):
        def advance(n):  # the world's own thread, between two cycles
            advance.k += n
            if advance.k == 6:
                os.kill(program_pids()[3], signal.SIGKILL)

        advance.k = 0
        yield advance

    monkeypatch.setattr(swarm_cli, "steps_bar", steps)
    trace = tmp_path / "swarm.npz"
    code = cli.main(
        ["swarm", "--transport", "zenoh", "--set", "steps=20", "--json", "--trace", str(trace)]
        + ["--deadline", "0.5"]
    )
    out, err = capsys.readouterr()
    assert code == 0, err
    result = json.loads(out)
    lost = result["swarm"]["lost"]
    assert lost == {"3": 6}
    why = result["swarm"]["lost_why"]["3"]  # its process ended, as its launcher saw
    assert why == "its process ended (killed by SIGKILL), printing nothing"
    assert f"uavtrack: note: program 3 lost at step 6: {why}\n" in err
    with np.load(trace) as arrays:
        assert not arrays["alive"][lost["3"] :, 3].any()
        assert arrays["alive"][:, [0, 1, 2, 4]].all()


@pytest.mark.slow  # 30 s of a realtime run: kept out of CI's 15 minutes
def test_programs_cannot_join_a_run_under_way(tmp_path):
    # the world started with --no-spawn, its programs by hand with their key files; once
    # the run is under way a program already running, one of another number, or one
    # whose number was lost cannot join: exit 2 with the reason
    scenario = uavtrack.Scenario(steps=60)  # 30 s at dt: time for the late programs
    joined, reached, done = {}, threading.Event(), {}

    def announce(run, endpoint, written):
        joined.update(run=run, endpoint=endpoint, keys=written)

    def progress(k):
        if k >= 4:
            reached.set()

    def world():
        try:
            done["swarm"] = run_swarm(
                scenario,
                "distributed",
                seed=5,
                transport="zenoh",
                spawn=False,
                keys=tmp_path,
                announce=announce,
                deadline=0.5,
                realtime=True,
                progress=progress,
            )
        except BaseException as exc:
            done["error"] = exc

    thread = threading.Thread(target=world)
    thread.start()
    assert wait_until(lambda: "keys" in joined or "error" in done)
    keyfiles = joined["keys"]
    assert [p.name for p in keyfiles] == [f"{joined['run']}-{i}.key" for i in range(5)]
    agent = [sys.executable, "-m", "uavtrack.cli", "agent", "--connect", joined["endpoint"]]
    programs = [
        subprocess.Popen(agent + ["--key", str(k)], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        for k in keyfiles
    ]
    try:
        assert reached.wait(300), done
        programs[2].kill()
        late = [
            (["--key", str(keyfiles[0])], "is already running"),
            (["--key", str(keyfiles[2])], "is under way"),
        ]
        tries = [
            subprocess.Popen(agent + args, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
            for args, _ in late
        ]  # together: a loaded machine starts them slowly, the run goes on meanwhile
        for proc, (_, message) in zip(tries, late, strict=True):
            _, err = proc.communicate(timeout=120)
            assert proc.returncode == 2 and message in err.decode(), err.decode()
        thread.join()
        for p in programs:  # they end with their world
            p.communicate(timeout=120)
    finally:
        for p in programs:
            if p.poll() is None:
                p.kill()
                p.communicate()
    assert done["swarm"].traffic.lost.get(2, -1) >= 4
    assert not any(k.exists() for k in keyfiles)  # the keys of a finished run are removed
    for i in (0, 1, 3, 4):
        assert programs[i].returncode == 0


# ------------------------------------------------------------------ TLS


def make_certificates(
    folder: Path,
    name: str = "swarm",
    host_days: tuple[float, float] = (-1 / 288, 1),
    ca_days: tuple[float, float] = (-1 / 288, 1),
    signer: dict[str, Path] | None = None,
) -> dict[str, Path]:
    """A CA and one certificate for 127.0.0.1 and localhost signed by it (PEM files; the
    private keys private to their owner, as openssl writes them). host_days, ca_days:
    the validity of each from and to, in days from now; signer: another set's CA signs
    the host certificate instead (the CA file written is still this set's)."""
    import datetime
    import ipaddress

    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    now = datetime.datetime.now(datetime.UTC)
    folder.mkdir(parents=True, exist_ok=True)

    def subject(cn):
        return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, cn)])

    def save(stem, key, cert):
        key_path, cert_path = folder / f"{stem}.key", folder / f"{stem}.pem"
        key_path.write_bytes(
            key.private_bytes(
                serialization.Encoding.PEM,
                serialization.PrivateFormat.PKCS8,
                serialization.NoEncryption(),
            )
        )
        key_path.chmod(0o600)
        cert_path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
        return key_path, cert_path

    def build(cn, issuer, public, signer_key, ca, days):
        builder = (
            x509.CertificateBuilder()
            .subject_name(subject(cn))
            .issuer_name(issuer)
            .public_key(public)
            .serial_number(x509.random_serial_number())
            .not_valid_before(now + datetime.timedelta(days=days[0]))
            .not_valid_after(now + datetime.timedelta(days=days[1]))
            .add_extension(x509.BasicConstraints(ca=ca, path_length=None), critical=True)
        )
        if not ca:
            builder = builder.add_extension(
                x509.SubjectAlternativeName(
                    [x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]
                ),
                critical=False,
            ).add_extension(
                x509.ExtendedKeyUsage(
                    [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
                ),
                critical=False,
            )
        return builder.sign(signer_key, hashes.SHA256())

    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca = build(f"{name} CA", subject(f"{name} CA"), ca_key.public_key(), ca_key, True, ca_days)
    ca_key_path, ca_path = save("ca", ca_key, ca)
    issuer, issuer_key = ca.subject, ca_key
    if signer is not None:
        issuer_key = serialization.load_pem_private_key(signer["ca_key"].read_bytes(), None)
        issuer = x509.load_pem_x509_certificate(signer["ca"].read_bytes()).subject
    key = ec.generate_private_key(ec.SECP256R1())
    cert = build(name, issuer, key.public_key(), issuer_key, False, host_days)
    key_path, cert_path = save("host", key, cert)
    return {"ca": ca_path, "cert": cert_path, "key": key_path, "ca_key": ca_key_path}


def tls_options(files):
    from uavtrack.agents.transport import ZenohOptions

    return ZenohOptions(None, str(files["ca"]), str(files["cert"]), str(files["key"]))


def test_a_swarm_over_mutual_tls_equals_the_simulator_and_refuses_strangers(tmp_path):
    from uavtrack.agents.transport import ZenohTransport
    from uavtrack.testing import assert_same_trace

    files = make_certificates(tmp_path / "swarm")
    foreign = make_certificates(tmp_path / "stranger", "stranger")
    scenario = uavtrack.Scenario(steps=10)
    told = {}
    checked = threading.Event()
    refused = {}

    def try_strangers(pids):  # between two cycles: two strangers knock on its port, and
        endpoint = told["endpoint"]  # a holder of the swarm's certificate (who gets in)
        for name, options, where in (
            ("another CA's certificate", tls_options(foreign), endpoint),
            ("no TLS at all", None, endpoint.replace("tls/", "tcp/")),
            ("the swarm's certificate", tls_options(files), endpoint),
        ):
            try:
                ZenohTransport([], [where], options).close()
                refused[name] = False
            except Exception:
                refused[name] = True
        checked.set()

    swarm = swarm_with(
        scenario,
        act=try_strangers,
        at=1,
        between=True,  # the world (and its endpoint) is up while they try
        zenoh=tls_options(files),
        announce=lambda run, endpoint, written: told.update(endpoint=endpoint),
    )
    assert told["endpoint"].startswith("tls/127.0.0.1:")
    assert checked.is_set() and refused == {
        "another CA's certificate": True,
        "no TLS at all": True,
        "the swarm's certificate": False,
    }
    assert_same_trace(swarm.result.trace, uavtrack.simulate(scenario, "distributed", seed=5).trace)


def test_the_program_processes_end_with_their_world_and_leave_nothing():
    scenario = uavtrack.Scenario(steps=4)
    seen = {}
    swarm_with(scenario, act=lambda pids: seen.update(pids), at=1)
    assert len(seen) == 5
    assert wait_until(lambda: not any(alive(p) for p in seen.values()), limit=30)
