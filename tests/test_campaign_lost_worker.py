"""A campaign survives a lost worker and says so (issue 31, cases R2-23 and R2-24).

R2-23: a worker started ``--no-nanny`` and killed mid-case is dropped by the scheduler
at once (its case started no process of its own that would keep its connections open),
the case runs again on the other worker within seconds, and no orphan is left.
R2-24: each case's attempts (worker, outcome, the reason it ran again) are in
``case.json``, ``campaign.json``, ``campaign.html`` and the progress lines."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path

import psutil
import pytest

from boomfmi.campaign import write_manifest
from test_campaign import fit_and_holdout

BIN = Path(sys.executable).parent

#: loaded into the victim worker (``dask worker --preload``): the first case that reaches
#: its report stage (diagnose's ``rig_model``, right after the FMUs' confirmation was
#: started) marks the file named by $BOOMFMI_TEST_PAUSE and waits there to be killed
PAUSE = '''
import os, time
import boomfmi.diagnose.report as report

_marker, _rig_model = os.environ["BOOMFMI_TEST_PAUSE"], report.rig_model


def rig_model(*args, **kwargs):
    try:
        fd = os.open(_marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        return _rig_model(*args, **kwargs)
    os.close(fd)
    time.sleep(600)
    return _rig_model(*args, **kwargs)


report.rig_model = rig_model
'''


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """Two short effect-free recordings of the virtual rig (fit and holdout)."""
    return fit_and_holdout(tmp_path_factory.mktemp("rec"), 3.0)


def _manifest(folder: Path, recordings: Path, machines, date="2025-01-06") -> Path:
    rows = []
    for m in machines:
        for role, src in (("fit", "fit.csv"), ("holdout", "hold.csv")):
            p = folder / m / f"{date}_{role}.csv"
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_bytes((recordings / src).read_bytes())
            rows.append({"machine": m, "date": date, "role": role, "recording": p})
    return write_manifest(folder / "manifest.csv", rows)


def _wait_for(predicate, timeout, what):
    t = time.monotonic()
    while time.monotonic() - t < timeout:
        value = predicate()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")


def _processes_named(token: str) -> list[psutil.Process]:
    """The live processes whose command line holds ``token`` (a forked child keeps its
    parent's)."""
    found = []
    for p in psutil.process_iter(["cmdline"]):
        try:
            if token in " ".join(p.info["cmdline"] or []) and p.status() != psutil.STATUS_ZOMBIE:
                found.append(p)
        except psutil.Error:
            continue
    return found


@pytest.mark.slow
def test_a_no_nanny_worker_killed_mid_case_is_dropped_at_once_and_the_case_records_both_attempts(tmp_path,
                                                                                                recordings):
    machines = ["m1", "m2", "m3"]
    manifest = _manifest(tmp_path, recordings, machines)
    (tmp_path / "pause.py").write_text(PAUSE)
    marker = tmp_path / "paused"
    victim_name = f"victim-{os.getpid()}-{tmp_path.name}"       # in its command line: finds its orphans
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1",
               DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED="False")
    procs = []
    try:
        sched_file = tmp_path / "scheduler.json"
        procs.append(subprocess.Popen([BIN / "dask", "scheduler", "--host", "127.0.0.1", "--port", "0",
                                       "--no-dashboard", "--dashboard-address", "127.0.0.1:0",     # loopback only
                                       "--scheduler-file", sched_file],
                                      cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        address = _wait_for(lambda: sched_file.is_file() and json.loads(sched_file.read_text() or "{}").get("address"),
                            60, "the scheduler")
        assert address.startswith("tcp://127.0.0.1:")
        workers = {}
        for name, extra, wenv in (("survivor", [], env),
                                  (victim_name, ["--preload", tmp_path / "pause.py"],
                                   dict(env, BOOMFMI_TEST_PAUSE=str(marker)))):
            workers[name] = subprocess.Popen([BIN / "dask", "worker", address, "--nthreads", "1", "--no-nanny",
                                              "--name", name, "--no-dashboard", "--dashboard-address", "127.0.0.1:0",
                                              "--host", "127.0.0.1", *extra],
                                             cwd=tmp_path, env=wenv, stdout=subprocess.DEVNULL,
                                             stderr=subprocess.DEVNULL)
            procs.append(workers[name])
        from distributed import Client
        with Client(address, timeout="20s") as watch:
            watch.wait_for_workers(2, timeout=60)
            addresses = {w["name"]: a for a, w in watch.scheduler_info()["workers"].items()}
        victim, survivor = addresses[victim_name], addresses["survivor"]
        campaign = subprocess.Popen([sys.executable, "-m", "boomfmi.cli", "campaign", manifest, "--out",
                                     tmp_path / "out", "--scheduler", address, "--ssp", tmp_path / "no.ssp"],
                                    cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        procs.append(campaign)
        _wait_for(marker.exists, 120, "a case on the victim worker to reach its report stage")
        # R2-23: inside a Dask worker a case starts no process of its own (before: a process
        # pool for the FMUs' confirmation, whose forked child kept the worker's connections)
        children = psutil.Process(workers[victim_name].pid).children(recursive=True)
        workers[victim_name].send_signal(signal.SIGKILL)
        killed = time.time()
        workers[victim_name].wait(10)
        try:
            stdout, stderr = campaign.communicate(timeout=90)
        except subprocess.TimeoutExpired:
            pytest.fail("the campaign did not finish within 90 s of the worker's kill: the scheduler did not "
                        f"drop the killed worker (its forked children: {[c.pid for c in children]})")
        assert children == [], "a case started processes of its own inside a Dask worker"
        orphans = _processes_named(victim_name)
        assert orphans == [], f"processes left of the killed worker: {orphans}"
        assert campaign.returncode == 0, stderr
        assert "Traceback" not in stderr

        out = tmp_path / "out"
        doc = json.loads((out / "campaign.json").read_text())
        # nothing lost: every case done, once, each with its outputs
        assert doc["run"]["cases"] == 3 and doc["run"]["failed"] == 0
        assert sorted(c["machine"] for c in doc["cases"]) == machines
        for c in doc["cases"]:
            assert c["status"] == "done" and c["worker"] == survivor, c     # the victim finished none
            for name in ("diagnosis.json", "report.html", "params.json", "case.json"):
                assert (out / c["folder"] / name).is_file(), (c["machine"], name)
        # R2-24: the killed case's two attempts, the lost worker and why
        hit = [c for c in doc["cases"] if any(a["outcome"] == "worker lost mid-case" for a in c["attempts"])]
        assert len(hit) == 1, [c["attempts"] for c in doc["cases"]]
        case = hit[0]
        first, second = case["attempts"][0], case["attempts"][-1]
        assert len(case["attempts"]) == 2, case["attempts"]
        assert (first["attempt"], first["worker"], first["lost"]) == (1, victim, True)
        assert "connection to the scheduler closed" in first["reason"]
        lost_after = datetime.fromisoformat(first["ended"]).timestamp() - killed
        assert -1.0 < lost_after < 10.0, f"the scheduler dropped the killed worker {lost_after:.1f} s after its kill"
        assert (second["attempt"], second["worker"], second["outcome"], second["lost"]) == (2, survivor, "done", False)
        assert case["worker"] == survivor
        record = json.loads((out / case["folder"] / "case.json").read_text())
        assert record["attempts"] == case["attempts"]
        assert doc["run"]["workers_lost"] == {victim: first["reason"]} and doc["run"]["cases_retried"] >= 1
        page = (out / "campaign.html").read_text()
        assert "1 worker(s) lost" in page and "2 attempts" in page and "worker lost mid-case" in page
        assert victim in page
        label = f"{case['machine']} {case['date']}"
        assert f"worker lost, case {label}" in stderr and "rescheduled" in stderr, stderr
        assert "1 worker(s) lost" in stderr and "3/3 cases" in stderr
        assert f"worker lost: {victim}" in stdout
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
                try:
                    p.wait(20)
                except subprocess.TimeoutExpired:
                    p.kill()
        for p in _processes_named(victim_name):      # an orphan of the killed worker (before the fix)
            p.kill()


def test_attempts_name_each_lost_worker_and_why_and_the_progress_says_so():
    """R2-24 without a cluster: Dask's events as the client gets them (a case starting on
    a worker; the scheduler removing a worker with the tasks it held)."""
    import dask
    from boomfmi.campaign.engine import Attempts, Progress
    text = []
    bar = Progress(3, 0, write=text.append, tty=False)
    tries = Attempts(note=bar.worker_lost)
    tries.expect("k1", "m1 2025-01-06")
    tries.expect("k2", "m2 2025-01-06")
    t0 = time.time()
    tries.started((t0, {"key": "k1", "worker": "tcp://127.0.0.1:1001"}))
    tries.started((t0, {"key": "not-ours", "worker": "tcp://127.0.0.1:1001"}))
    tries.removed((t0 + 1, {"action": "gather", "count": 1}))                      # not a removal: ignored
    tries.removed((t0 + 2, {"action": "remove-worker", "worker": "tcp://127.0.0.1:1001", "expected": False,
                            "processing-tasks": {"k1", "k2", "not-ours"}, "lost-computed-tasks": set(),
                            "stimulus_id": "handle-worker-cleanup-1234.5"}))
    lines = "".join(text)
    assert "worker lost, case m1 2025-01-06 rescheduled: tcp://127.0.0.1:1001 (its connection to the scheduler " \
           "closed" in lines and "attempt 1: worker lost mid-case" in lines
    assert "worker lost, case m2 2025-01-06 rescheduled" in lines and "worker lost before the case started" in lines
    assert "0/3 cases (1 worker(s) lost, 2 case(s) rescheduled)" in lines and "not-ours" not in lines
    tries.started((t0 + 3, {"key": "k1", "worker": "tcp://127.0.0.1:1002"}))
    one = tries.finish("k1", {"status": "done", "worker": "tcp://127.0.0.1:1002"})
    assert [(a["attempt"], a["worker"], a["outcome"], a["lost"]) for a in one] == [
        (1, "tcp://127.0.0.1:1001", "worker lost mid-case", True), (2, "tcp://127.0.0.1:1002", "done", False)]
    assert one[0]["started"] and one[0]["ended"] and "killed" in one[0]["reason"] and one[1]["reason"] is None
    two = tries.finish("k2", {"status": "failed", "worker": "tcp://127.0.0.1:1002"})      # its start not heard
    assert [(a["worker"], a["started"], a["outcome"]) for a in two] == [
        ("tcp://127.0.0.1:1001", None, "worker lost before the case started there"),
        ("tcp://127.0.0.1:1002", None, "failed")]
    # beyond allowed-failures the scheduler gives up: said so, not "rescheduled"; a silent worker is named
    text.clear()
    with dask.config.set({"distributed.scheduler.allowed-failures": 1}):
        tries = Attempts(note=bar.worker_lost)
    tries.expect("k3", "m3 2025-01-06")
    for n, (worker, stimulus) in enumerate((("tcp://127.0.0.1:1003", "check-worker-ttl-99.0"),
                                            ("tcp://127.0.0.1:1004", "handle-worker-cleanup-100.0"))):
        tries.started((t0 + 10 * n, {"key": "k3", "worker": worker}))
        tries.removed((t0 + 10 * n + 5, {"action": "remove-worker", "worker": worker, "expected": False,
                                         "processing-tasks": ["k3"], "stimulus_id": stimulus}))
    lines = "".join(text)
    assert "case m3 2025-01-06 rescheduled: tcp://127.0.0.1:1003 (it sent no heartbeat within " \
           "distributed.scheduler.worker-ttl" in lines
    assert "case m3 2025-01-06 not rescheduled: lost with 2 workers (distributed.scheduler.allowed-failures 1)" in lines
    gave_up = tries.finish("k3", None)                          # KilledWorker: no result of its own
    assert [(a["worker"], a["lost"]) for a in gave_up] == [("tcp://127.0.0.1:1003", True), ("tcp://127.0.0.1:1004", True)]


def test_no_process_pool_is_started_inside_a_dask_worker():
    """R2-23's cause: diagnose started a process pool wherever the process was not
    daemonic, a ``--no-nanny`` worker included (and so did the candidates' fits with
    workers > 1)."""
    from distributed import Client, LocalCluster
    from boomfmi.diagnose.attribute import may_start_processes
    assert may_start_processes()
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address="127.0.0.1:0", worker_dashboard_address="127.0.0.1:0") as cluster, \
            Client(cluster) as client:
        assert client.submit(may_start_processes, pure=False).result(timeout=30) is False
