"""Running a campaign's cases on Dask (``dask.distributed``).

* **Where.**  A :class:`distributed.LocalCluster` by default: one worker process per
  core (``workers``), one thread each (a case is single-threaded NumPy and SciPy; the
  nanny also sets ``OMP_NUM_THREADS=1``), no dashboard, and neither Dask's profiler
  nor its ``MALLOC_TRIM_THRESHOLD_``, which slow a case down (:data:`LOCAL_WORKER_CONFIG`).  Or any running scheduler by
  its address (``scheduler="tcp://host:8786"``), whose workers need boomfmi installed
  and nothing else: each case's recordings travel with it as bytes
  (:func:`~.case.case_spec`), and its outputs come back the same way.
* **Resume.**  Each case's result is written as it completes, into
  ``OUT/cases/<machine>/<date>/``: the files ``boomfmi identify`` and ``boomfmi
  diagnose`` write, then ``case.json`` (moved into place last, so a folder without it
  is no result).  A re-run skips each case whose ``case.json`` says done for the very
  same input (the fingerprint of its recordings' and sidecars' bytes and roles, and
  the ``ssp`` given); a failed case, or one whose recordings or ``ssp`` changed, is run
  again.
* **Failures.**  A case that raises is reported with its error and traceback in its
  ``case.json`` and in ``campaign.json``; the rest go on.  A worker lost in mid-case
  (killed, out of memory, its machine gone) is the scheduler's to handle: the case is
  started again on another worker, up to ``distributed.scheduler.allowed-failures``
  times (default 3), after which it is reported failed (``KilledWorker``).  Results
  reach the client once per case, and only the client writes: a case is never
  written twice, nor half.  The scheduler sees a killed worker go at once, whatever
  its kind (with or without a nanny), because a case starts no process of its own
  there (``diagnose.attribute.may_start_processes``: a forked child would hold the dead
  worker's connections open until ``worker-ttl``).  Each case's attempts (the worker
  of each, when it started and ended, and why it was run again: the scheduler's
  reason for removing the worker) are recorded from Dask's events (:class:`Attempts`)
  in its ``case.json``, ``campaign.json`` and ``campaign.html``.
* **Progress.**  ``progress`` is told of every case as it completes, and of each
  worker lost with a case ("worker lost, case ... rescheduled") (:class:`Progress`);
  the CLI draws a bar from it.
"""
from __future__ import annotations

import json
import logging
import os
import sys
import threading
import time
from collections import deque
from datetime import datetime, timezone
from pathlib import Path

from .._json import dumps
from ..outputs import OutputSet
from .case import CASE_STARTED, CASE_VERSION, case_spec, run_case
from .manifest import Manifest, read_manifest, slug

#: seconds to wait for a scheduler's first worker
WORKER_WAIT = 60.0
#: Dask settings of the local cluster's workers.  A case is many small NumPy and SciPy
#: calls; two of Dask's defaults slow that down: its statistical profiler (a sample of
#: the running task's stack every 10 ms: a loop of small NumPy calls ran 1.6 times as
#: long in a worker with it as without it, or in a plain process), and glibc's trim
#: threshold that its nannies set (64 KiB: short-lived arrays go back to the system and
#: come again; a case 10 % slower or more).  Off for the local cluster;
#: docs/campaign-scaling.md.
LOCAL_WORKER_CONFIG = {"distributed.worker.profile.enabled": False,
                       "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}


class Progress:
    """The campaign's progress: counts, elapsed time, an estimate of what is left, and a
    text bar.  ``write(text)`` receives the bar (and a line per finished case)."""

    def __init__(self, total: int, skipped: int, write=None, tty: bool | None = None):
        self.total, self.skipped, self.done, self.failed = total, skipped, 0, 0
        self.lost: set[str] = set()          # workers lost with a case of this campaign
        self.rescheduled = 0                 # cases sent back to the scheduler by a lost worker
        self.t0 = time.perf_counter()
        self.write = write
        self.tty = sys.stderr.isatty() if tty is None else tty
        self._lock = threading.Lock()        # lines come from the client's event loop too

    def bar(self) -> str:
        n = self.skipped + self.done + self.failed
        width = 30
        fill = int(round(width * n / self.total)) if self.total else width
        elapsed = time.perf_counter() - self.t0
        ran = self.done + self.failed
        left = self.total - n
        eta = f", about {_duration(elapsed / ran * left)} left" if ran and left else ""
        extra = ", ".join(s for s in (f"{self.skipped} done before" if self.skipped else "",
                                      f"{self.failed} failed" if self.failed else "",
                                      f"{len(self.lost)} worker(s) lost" if self.lost else "",
                                      f"{self.rescheduled} case(s) rescheduled" if self.rescheduled else "") if s)
        return (f"[{'#' * fill}{'.' * (width - fill)}] {n}/{self.total} cases"
                + (f" ({extra})" if extra else "") + f", {_duration(elapsed)}{eta}")

    def case(self, line: str, failed: bool) -> None:
        with self._lock:
            if failed:
                self.failed += 1
            else:
                self.done += 1
            self._line(line)

    def worker_lost(self, line: str, worker: str, rescheduled: bool) -> None:
        """A worker was lost holding a case (:class:`Attempts`): ``line`` says which, and
        whether it was rescheduled."""
        with self._lock:
            self.lost.add(worker)
            self.rescheduled += bool(rescheduled)
            self._line(line)

    def _line(self, line: str) -> None:
        if self.write:
            if self.tty:
                self.write("\r\033[K" + line + "\n" + self.bar())
            else:
                self.write(line + "\n" + self.bar() + "\n")

    def start(self) -> None:
        if self.write:
            self.write(self.bar() + ("" if self.tty else "\n"))

    def finish(self) -> None:
        if self.write and self.tty:
            self.write("\n")


def _duration(s: float) -> str:
    s = int(round(s))
    return f"{s // 3600}h{s % 3600 // 60:02d}m" if s >= 3600 else f"{s // 60}m{s % 60:02d}s" if s >= 60 else f"{s}s"


def _iso(t: float) -> str:
    return datetime.fromtimestamp(t, timezone.utc).isoformat(timespec="milliseconds")


def removal_reason(msg: dict) -> str:
    """Why the scheduler removed a worker, from its "remove-worker" event."""
    stimulus = str(msg.get("stimulus_id") or "")
    if msg.get("expected"):
        return "the worker left in an orderly way (retired or closed)"
    if stimulus.startswith("handle-worker-cleanup"):
        return ("its connection to the scheduler closed: the worker process died or was killed, "
                "or its machine went away")
    if stimulus.startswith("check-worker-ttl"):
        return "it sent no heartbeat within distributed.scheduler.worker-ttl"
    return f"the scheduler removed it ({stimulus or 'no reason given'})"


class Attempts:
    """Each case's attempts in this run, from Dask's events: each attempt's task says
    where it starts (:data:`~.case.CASE_STARTED`, from its worker), and the scheduler
    says which worker it removed, why, and which of the cases it held ("remove-worker"
    on its topic "all": those it ran or had queued, and results the client had not yet
    fetched).  Each such case is started again elsewhere, up to
    ``distributed.scheduler.allowed-failures`` times (as this client's configuration
    gives it).  The handlers run on the client's event loop; ``note(line, worker,
    rescheduled)`` is told of each case a lost worker sends back
    (:meth:`Progress.worker_lost`)."""

    def __init__(self, note=None):
        import dask
        import distributed  # noqa: F401  (its configuration's defaults)
        self.note = note
        self.allowed = int(dask.config.get("distributed.scheduler.allowed-failures"))
        self._lock = threading.Lock()
        self._labels: dict[str, str] = {}            # task key -> its case's label
        self._tries: dict[str, list[dict]] = {}
        self._failures: dict[str, int] = {}          # the scheduler's count (not for a retired worker)

    def expect(self, key: str, label: str) -> None:
        with self._lock:
            self._labels[key] = label

    def started(self, event) -> None:
        _, msg = event
        if not isinstance(msg, dict):
            return
        with self._lock:
            if msg.get("key") in self._labels:
                self._tries.setdefault(msg["key"], []).append(
                    {"worker": msg.get("worker"), "started": _iso(event[0]), "ended": None,
                     "outcome": "running", "lost": False, "reason": None})

    def removed(self, event) -> None:
        t, msg = event
        if not isinstance(msg, dict) or msg.get("action") != "remove-worker":
            return
        worker, reason = msg.get("worker"), removal_reason(msg)
        lines = []
        with self._lock:
            for kind, keys in (("ran", msg.get("processing-tasks")), ("result", msg.get("lost-computed-tasks"))):
                for key in sorted(str(k) for k in keys or ()):
                    if key not in self._labels:
                        continue
                    tries = self._tries.setdefault(key, [])
                    mine = next((a for a in reversed(tries) if a["worker"] == worker and a["outcome"] == "running"), None)
                    if mine is None:        # queued there: not started, as far as the scheduler heard
                        mine = {"worker": worker, "started": None}
                        tries.append(mine)
                    mine.update(ended=_iso(t), lost=True, reason=reason, outcome=(
                        "its result lost with the worker before the client fetched it" if kind == "result" else
                        "worker lost mid-case" if mine["started"] else "worker lost before the case started there"))
                    failures = self._failures[key] = self._failures.get(key, 0) + (not msg.get("expected"))
                    again = failures <= self.allowed
                    what = ("rescheduled" if again else
                            f"not rescheduled: lost with {failures} workers (distributed.scheduler.allowed-failures "
                            f"{self.allowed})")
                    lines.append((f"worker lost, case {self._labels[key]} {what}: {worker} ({reason}; "
                                  f"attempt {len(tries)}: {mine['outcome']})", again))
        for line, again in lines:
            if self.note:
                self.note(line, worker, again)

    def finish(self, key: str, result: dict | None) -> list[dict]:
        """The case's attempts, numbered, ``result`` (its worker's, None where the
        scheduler gave up on it) the last."""
        with self._lock:
            tries = self._tries.pop(key, [])
            self._labels.pop(key, None)
            self._failures.pop(key, None)
        if result is not None:
            last = next((a for a in reversed(tries) if a["outcome"] == "running"
                         and a["worker"] == result.get("worker")), None)
            if last is None:              # not told (no Dask worker, or its event not through)
                last = {"worker": result.get("worker"), "started": None, "lost": False, "reason": None}
                tries.append(last)
            last.update(outcome=result["status"], ended=_iso(time.time()))
        for a in tries:
            if a["outcome"] == "running":       # started, then no word of it: another attempt won
                a["outcome"] = "no result (the scheduler ran the case again elsewhere)"
        return [{"attempt": i + 1, **a} for i, a in enumerate(tries)]


def case_folder(out: Path, case) -> Path:
    return Path(out) / "cases" / case.folder


def load_done(folder: Path, fingerprint: str) -> dict | None:
    """The case record in ``folder`` where it is done for this input; else None."""
    try:
        rec = json.loads((folder / "case.json").read_text())
    except (OSError, ValueError):
        return None
    if rec.get("status") == "done" and rec.get("fingerprint") == fingerprint:
        return rec
    return None


def write_case(folder: Path, case, result: dict) -> dict:
    """Write a case's outputs and its ``case.json`` (last) into ``folder``, as one set
    (files an earlier run of the case left and this one did not write are removed);
    return the record."""
    record = {"machine": case.machine, "date": case.date, "status": result["status"],
              "fingerprint": result.get("fingerprint"), "case_version": CASE_VERSION,
              "recordings": {role: [str(e.recording) for e in case.role(role)] for role in ("fit", "holdout")},
              "worker": result.get("worker"), "wall_s": result.get("wall_s"),
              "attempts": result.get("attempts") or [],
              "finished": datetime.now(timezone.utc).isoformat(timespec="seconds"),
              "error": result.get("error"), "summary": result.get("summary"),
              "files": sorted(result.get("outputs", {})), "log": result.get("log", []),
              "traceback": result.get("traceback")}
    old = [p.name for p in folder.iterdir() if p.is_file() and not p.name.startswith(".")] if folder.is_dir() else []
    with OutputSet(folder, stale=old) as files:
        for name, data in result.get("outputs", {}).items():
            files.path(name).write_bytes(data)
        files.path("case.json").write_text(dumps(record, indent=1))
    return record


def _failure(fingerprint: str, error: str) -> dict:
    return {"status": "failed", "error": error, "fingerprint": fingerprint, "outputs": {}, "summary": None,
            "log": [], "worker": None, "wall_s": None, "traceback": None}


class Engine:
    """A Dask client for a campaign: the given ``client``, a scheduler's by
    ``scheduler`` address, or a LocalCluster of ``workers`` processes (default: one per
    core).  A context manager; closes only what it started."""

    def __init__(self, scheduler: str | None = None, workers: int | None = None, client=None):
        self.client, self.cluster, self._own = client, None, client is None
        self.scheduler, self.workers = scheduler, workers
        if scheduler and workers:
            raise ValueError("--workers sizes the local cluster; a scheduler given by --scheduler has its own workers")
        if workers is not None and workers < 1:
            raise ValueError(f"--workers {workers}: give 1 or more")

    def __enter__(self):
        import dask
        from distributed import Client, LocalCluster
        if self.client is not None:
            return self
        if self.scheduler:
            try:
                self.client = Client(self.scheduler, timeout="20s")
            except OSError as e:
                raise OSError(f"cannot reach the Dask scheduler at {self.scheduler}: {e}") from None
            try:
                self.client.wait_for_workers(1, timeout=WORKER_WAIT)
            except Exception:
                self.client.close()
                raise RuntimeError(f"the Dask scheduler at {self.scheduler} has no worker "
                                   f"(none joined within {WORKER_WAIT:g} s)") from None
        else:
            n = self.workers or os.cpu_count() or 1
            with dask.config.set(LOCAL_WORKER_CONFIG):
                self.cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                            dashboard_address=None, silence_logs=logging.ERROR)
            self.client = Client(self.cluster)
        return self

    def __exit__(self, *exc):
        if self._own:
            if self.client is not None:
                self.client.close()
            if self.cluster is not None:
                self.cluster.close()

    @property
    def address(self) -> str:
        return self.client.scheduler.address

    def slots(self) -> int:
        return max(1, sum(self.client.nthreads().values()))


def run_cases(manifest: Manifest, out, engine: Engine, ssp=None, progress=None) -> list[dict]:
    """Every case of ``manifest`` on ``engine``: the records of those done before (same
    input) as they are, the others run, each written as it completes.  Returns the
    records in the manifest's order."""
    from distributed import as_completed
    out = Path(out)
    records: dict[tuple, dict] = {}
    todo = deque()
    for case in manifest.cases:
        spec = case_spec(case, ssp)          # its files read and hashed once: kept for the run
        done = load_done(case_folder(out, case), spec["fingerprint"])
        if done is not None:
            records[case.key] = dict(done, resumed=True)
        else:
            todo.append((case, spec))
    bar = Progress(len(manifest.cases), len(records), progress)
    bar.start()
    running: dict = {}
    pending = as_completed()
    tries = Attempts(note=bar.worker_lost)
    client = engine.client
    client.subscribe_topic("all", tries.removed)              # the scheduler's: a worker removed
    client.subscribe_topic(CASE_STARTED, tries.started)       # each case's: an attempt starts

    def submit():
        while todo and len(running) < 2 * engine.slots() + 1:
            case, spec = todo.popleft()
            key = f"boomfmi-case-{slug(case.machine)}-{slug(case.date)}-{spec['fingerprint'][:12]}"
            fut = engine.client.submit(run_case, spec, key=key, pure=False)
            running[fut.key] = (case, spec["fingerprint"])
            tries.expect(fut.key, case.label)
            pending.add(fut)
    try:
        submit()
        for fut in pending:
            case, fp = running.pop(fut.key)
            try:
                result = fut.result()
            except Exception as e:       # the case's worker lost too often, the scheduler gone, ...
                name = type(e).__name__
                hint = (" (the case's worker died each time it ran it: distributed.scheduler.allowed-failures)"
                        if name == "KilledWorker" else "")
                result = _failure(fp, f"{name}: {e}{hint}")
                result["attempts"] = tries.finish(fut.key, None)
            else:
                result["attempts"] = tries.finish(fut.key, result)
            fut.release()
            rec = write_case(case_folder(out, case), case, result)
            records[case.key] = rec
            failed = rec["status"] != "done"
            what = (f"FAILED: {rec['error']}" if failed else
                    f"verdict {rec['summary'].get('verdict')}" if rec["summary"].get("judgeable") else
                    f"not judgeable: {rec['summary'].get('reason')}")
            before = "".join(f"; attempt {a['attempt']} on {a['worker']}: {a['outcome']}"
                             for a in rec["attempts"] if a["lost"])
            bar.case(f"{case.label}: {what} ({rec['wall_s'] or 0:.0f} s on {rec['worker'] or '-'}{before})", failed)
            submit()
    except BaseException:
        for f in list(pending.futures):
            f.cancel()
        raise
    finally:
        for topic in ("all", CASE_STARTED):
            if client.status == "running":
                client.unsubscribe_topic(topic)
        bar.finish()
    return [records[c.key] for c in manifest.cases]


def run_campaign(manifest, out, scheduler: str | None = None, workers: int | None = None, ssp=None,
                 progress=None, client=None) -> dict:
    """``boomfmi campaign``: check the manifest (a :class:`~.manifest.ManifestError`
    before any work), run its cases on Dask (see the module), then write
    ``campaign.json``, ``campaign.html`` and the trend plots into ``out``.  Returns the
    campaign document.  ``progress(text)`` gets the progress bar's text."""
    manifest = manifest if isinstance(manifest, Manifest) else read_manifest(manifest)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"{out}: not a folder; --out names the campaign's output folder")
    from .report import write_campaign
    t0 = time.perf_counter()
    with Engine(scheduler, workers, client) as engine:
        address = engine.address
        slots = engine.slots()
        records = run_cases(manifest, out, engine, ssp=ssp, progress=progress)
    run = {"manifest": str(Path(manifest.path).resolve()), "scheduler": scheduler or "local",
           "address": address, "worker_threads": slots, "cases": len(records),
           "ran": sum(not r.get("resumed") for r in records), "resumed": sum(bool(r.get("resumed")) for r in records),
           "failed": sum(r["status"] != "done" for r in records), "wall_s": round(time.perf_counter() - t0, 2)}
    lost = [a for r in records if not r.get("resumed") for a in r.get("attempts") or [] if a["lost"]]
    run["workers_lost"] = {a["worker"]: a["reason"] for a in lost}       # this run's, each with why
    run["cases_retried"] = sum(any(a["lost"] for a in r.get("attempts") or []) for r in records if not r.get("resumed"))
    return write_campaign(out, manifest, records, run)


__all__ = ["WORKER_WAIT", "LOCAL_WORKER_CONFIG", "Progress", "removal_reason", "Attempts", "case_folder", "load_done",
           "write_case", "Engine", "run_cases", "run_campaign"]
