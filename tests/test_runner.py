import json

import numpy as np
import pytest

import uavtrack
from uavtrack.errors import UsageError
from uavtrack.experiments import jobs as job_lists
from uavtrack.experiments import store as runner


def small_jobs(trials=4, chunk=2):
    scenario = uavtrack.Scenario(steps=25)
    return [
        j
        for m in ("distributed", "greedy")
        for j in job_lists.trial_jobs(scenario, {}, m, trials, chunk, seed=3)
    ]


def manifest(**extra):
    return {
        "kind": "test",
        "seed": 3,
        "plan": {"trials": 4},
        "scenario": uavtrack.Scenario().model_dump(),
        **extra,
    }


def without_timing(metrics):
    return {k: v for k, v in metrics.items() if k not in ("decision_time_ms", "decision_wall_ms")}


def test_interrupted_run_resumes_without_recomputing(tmp_path, monkeypatch):
    jobs = small_jobs()
    seen = []

    def stop_after_two(job):
        seen.append(job.key)
        if len(seen) == 2:
            raise KeyboardInterrupt

    with runner.Store(tmp_path / "out", manifest()) as store, pytest.raises(KeyboardInterrupt):
        runner.execute(jobs, store, workers=1, progress=False, on_result=stop_after_two)
    assert sorted(p.stem for p in store.raw.glob("*.json")) == sorted(seen)
    assert not list(store.raw.glob(".*"))  # no temporary files left
    ran = []
    monkeypatch.setattr(
        runner, "run_job", lambda job: ran.append(job.key) or job_lists.run_job(job)
    )
    with runner.Store(tmp_path / "out", manifest()) as again:
        skipped, failed = runner.execute(jobs, again, workers=1, progress=False)
        assert skipped == 2 and not failed
        assert sorted(ran) == sorted(j.key for j in jobs if j.key not in seen)
        assert all(again.done(j) for j in jobs)


def test_failed_job_is_recorded_and_others_finish(tmp_path, monkeypatch):
    jobs = small_jobs()
    bad = jobs[1].key

    def flaky(job):
        if job.key == bad:
            raise RuntimeError("sensor exploded")
        return job_lists.run_job(job)

    monkeypatch.setattr(runner, "run_job", flaky)
    store = runner.Store(tmp_path / "out", manifest())
    skipped, failed = runner.execute(jobs, store, workers=1, progress=False)
    assert [j.key for j in failed] == [bad]
    record = json.loads((store.failed / f"{bad}.json").read_text())
    assert "sensor exploded" in record["error"]
    assert all(store.done(j) for j in jobs if j.key != bad) and not store.done(jobs[1])
    # the next run retries only the failed job and clears its record
    monkeypatch.setattr(runner, "run_job", job_lists.run_job)
    skipped, failed = runner.execute(jobs, store, workers=1, progress=False)
    assert skipped == len(jobs) - 1 and not failed
    assert not (store.failed / f"{bad}.json").exists()


def test_store_refuses_other_scenario_seed_or_code(tmp_path, monkeypatch):
    runner.Store(tmp_path / "out", manifest()).close()
    other = manifest()
    other["scenario"]["comm_range"] = 10.0
    with pytest.raises(UsageError, match=r"different scenario \(comm_range 50.0, now 10.0\)"):
        runner.Store(tmp_path / "out", other)
    with pytest.raises(UsageError, match="different seed"):
        runner.Store(tmp_path / "out", {**manifest(), "seed": 4})
    monkeypatch.setattr(runner, "code_hash", lambda: "0123456789abcdef")
    with pytest.raises(UsageError, match="different uavtrack code"):
        runner.Store(tmp_path / "out", manifest())
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "notes.txt").write_text("mine")
    with pytest.raises(UsageError, match="not an uavtrack results folder"):
        runner.Store(tmp_path / "junk", manifest())


def collect(store, jobs):
    return {j.key: without_timing(store.load(j)) for j in jobs}


@pytest.mark.integration
def test_same_results_with_any_number_of_workers(tmp_path):
    jobs = small_jobs()
    one = runner.Store(tmp_path / "one", manifest())
    runner.execute(jobs, one, workers=1, progress=False)
    two = runner.Store(tmp_path / "two", manifest())
    runner.execute(jobs, two, workers=2, progress=False)
    assert collect(one, jobs) == collect(two, jobs)


@pytest.mark.integration
def test_dask_local_cluster_gives_the_local_results(tmp_path):
    pytest.importorskip("dask.distributed")
    jobs = small_jobs(trials=2, chunk=1)
    local = runner.Store(tmp_path / "local", manifest())
    runner.execute(jobs, local, workers=1, progress=False)
    dask = runner.Store(tmp_path / "dask", manifest())
    runner.execute(jobs, dask, engine="dask", workers=2, progress=False)
    assert collect(local, jobs) == collect(dask, jobs)


def test_code_hash_is_stable():
    assert runner.code_hash() == runner.code_hash()
    assert len(runner.code_hash()) == 16


@pytest.mark.integration
def test_fault_realisations_do_not_depend_on_the_workers(tmp_path):
    scenario = uavtrack.Scenario(steps=25).with_overrides(
        {"faults.loss": 0.3, "faults.failure_rate": 0.01, "faults.position_std": 2.0}
    )
    jobs = job_lists.trial_jobs(scenario, {}, "distributed", 4, 1, seed=3)
    with runner.Store(tmp_path / "one", manifest()) as one:
        runner.execute(jobs, one, workers=1, progress=False)
        a = collect(one, jobs)
    with runner.Store(tmp_path / "two", manifest()) as two:
        runner.execute(jobs, two, workers=2, progress=False)
        b = collect(two, jobs)
    assert a == b
    whole = job_lists.run_job(job_lists.trial_jobs(scenario, {}, "distributed", 4, 4, 3)[0])
    assert (
        np.concatenate([a[j.key]["observation_rate"] for j in jobs]).tolist()
        == whole["observation_rate"]
    )


def test_a_lock_file_that_is_a_link_is_refused_and_its_target_kept(tmp_path):
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes\n")
    out = tmp_path / "out"
    runner.Store(out, manifest()).close()
    (out / ".lock").unlink(missing_ok=True)
    (out / ".lock").symlink_to(notes)
    with pytest.raises(UsageError, match=r"\.lock is a symbolic link"):
        runner.Store(out, manifest())
    assert notes.read_text() == "my notes\n"
    (out / ".lock").unlink()
    (out / ".lock").mkdir()
    with pytest.raises(UsageError, match=r"\.lock is not a regular file"):
        runner.Store(out, manifest())


def test_the_writability_probe_never_writes_through_a_link(tmp_path, monkeypatch):
    # the probe has a name of its own, created exclusively: a link planted at any name
    # it could have had stays a link to an untouched file
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes\n")
    out = tmp_path / "out"
    import os

    for folder in (out / "raw", out / "failed"):
        folder.mkdir(parents=True)
        (folder / f".probe-{os.getpid()}").symlink_to(notes)
    runner.Store(out, manifest()).close()
    assert notes.read_text() == "my notes\n"


def test_a_clean_run_leaves_no_lock_file_and_no_empty_failed_folder(tmp_path):
    jobs = small_jobs(trials=2)
    with runner.Store(tmp_path / "out", manifest()) as store:
        assert (tmp_path / "out" / ".lock").exists()  # held while the store is open
        runner.execute(jobs, store, workers=1, progress=False)
    names = {p.name for p in (tmp_path / "out").iterdir()}
    assert names == {"manifest.json", "raw"}


def test_every_rejection_of_a_job_file_is_kept(tmp_path):
    jobs = small_jobs(trials=2)
    out = tmp_path / "out"
    with runner.Store(out, manifest()) as store:
        runner.execute(jobs, store, workers=1, progress=False)
    path = out / "raw" / f"{jobs[0].key}.json"
    for attempt in range(3):  # edited again and again: each piece of evidence stays
        path.write_text(json.dumps({"edited": attempt}))
        with runner.Store(out, manifest()) as store:
            assert not store.done(jobs[0])
            runner.execute(jobs, store, workers=1, progress=False)
    rejected = sorted((out / "failed").glob(f"{jobs[0].key}.rejected*.json"))
    assert len(rejected) == 3
    assert sorted(json.loads(p.read_text())["content"] for p in rejected) == [
        json.dumps({"edited": a}) for a in range(3)
    ]


def test_a_long_label_makes_a_short_unique_file_name():
    from uavtrack import Scenario
    from uavtrack.experiments.jobs import Job

    long = ",".join(f"tracker.transition=[{i}]" * 3 for i in range(20))
    a = Job(
        kind="trials",
        label=long,
        method="distributed",
        scenario=Scenario(),
        first=0,
        count=25,
        seed=0,
    )
    b = Job(
        kind="trials",
        label=long + "x",
        method="distributed",
        scenario=Scenario(),
        first=0,
        count=25,
        seed=0,
    )
    assert len(a.key) < 200 and a.key != b.key
    short = Job(
        kind="trials",
        label="comm_range=10",
        method="greedy",
        scenario=Scenario(),
        first=25,
        count=25,
        seed=0,
    )
    assert short.key == "trials__comm_range=10__greedy__t025-049"  # as it always was
