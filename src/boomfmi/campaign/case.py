"""One case of a campaign (a machine on a date), as a worker runs it.

The client sends the case's recordings as bytes (:func:`case_spec`), so a worker needs
no view of the client's files: a cluster's workers on other machines get the same
input.  :func:`run_case` writes them into a temporary folder, runs the identification
(``params.json`` with the 95 % intervals, ``params.ssv``, ``params.png``) and the
diagnosis (``diagnosis.json``, ``report.html``, its PNGs) exactly as ``boomfmi
identify`` and ``boomfmi diagnose`` do (a case of the whole excavator's recordings: its
diagnosis per joint, ``diagnose.report.diagnose``, which identifies the baseline per joint
and writes ``diagnosis.json`` and ``report.html``), and returns every file written, with the
temporary paths in their texts put back to the recordings' own, and a summary for the
campaign's trends.  A case that fails returns its error (never raises): the rest of
the campaign goes on.
"""
from __future__ import annotations

import functools
import hashlib
import html
import json
import os
import socket
import tempfile
import time
import traceback
from pathlib import Path

from .. import __version__
from .._json import plain

#: bump when what a case computes changes: a campaign re-run then redoes its cases
CASE_VERSION = 1


def case_spec(case, ssp=None) -> dict:
    """What a worker needs to run ``case`` (a :class:`~.manifest.Case`): its recordings'
    and sidecars' bytes, and the fingerprint that says whether a result on disk is of
    this very input (the files' names, roles and bytes, ``ssp`` where given, boomfmi's
    version and :data:`CASE_VERSION`)."""
    files, digest = [], hashlib.sha256(f"boomfmi-{__version__}-case-{CASE_VERSION}".encode())
    names: set[str] = set()
    for e in sorted(case.entries, key=lambda e: (e.role, e.line)):
        name = e.recording.name if e.recording.suffix == ".csv" else e.recording.name + ".csv"
        base, k = name, 0
        while name in names:                   # two recordings of one name, from two folders
            k += 1                             # (and a third may be called 1_NAME already)
            name = f"{k}_{base}"
        names.add(name)
        csv_bytes = e.recording.read_bytes()
        own = e.recording.with_suffix(".json")
        side_path = e.sidecar or (own if own.is_file() else None)
        side = side_path.read_bytes() if side_path else None
        files.append({"role": e.role, "name": name, "source": str(e.recording),
                      "sidecar_source": str(side_path) if side_path else None, "csv": csv_bytes, "sidecar": side})
        for part in (e.role.encode(), name.encode(), hashlib.sha256(csv_bytes).digest(),
                     hashlib.sha256(side or b"").digest()):
            digest.update(len(part).to_bytes(8, "little") + part)
    if ssp:                  # the confirmation's system (none given: the default's, as before)
        part = f"ssp={ssp}".encode()
        digest.update(len(part).to_bytes(8, "little") + part)
    return {"machine": case.machine, "date": case.date, "files": files, "kind": getattr(case, "kind", "boom"),
            "ssp": str(ssp) if ssp else None, "fingerprint": digest.hexdigest()}


#: the Dask event topic on which a case tells where each of its attempts starts: ``{"key":
#: its task's key, "worker": the worker's address}`` (the engine's record of attempts)
CASE_STARTED = "boomfmi-case-started"


def _worker_name() -> str:
    try:
        from distributed import get_worker
        return get_worker().address
    except (ImportError, ValueError):
        return f"{socket.gethostname()}:{os.getpid()}"


def _announce(worker: str) -> None:
    """Within a Dask worker's task: tell the client, through the scheduler, that this
    attempt of the case starts on ``worker`` (:data:`CASE_STARTED`).  Outside a Dask
    worker's task (a plain loop over cases), nothing: the case runs all the same."""
    try:
        from distributed import get_worker
        w = get_worker()
        w.log_event(CASE_STARTED, {"key": str(w.get_current_task()), "worker": worker})
    except (ImportError, ValueError, KeyError):    # no Dask, no worker, no task: nothing to tell
        return


def run_case(spec: dict) -> dict:
    """Identify and diagnose one case from :func:`case_spec`'s ``spec``.  Returns
    ``{"status": "done" | "failed", "outputs": {name: bytes}, "summary", "error",
    "traceback", "log", "wall_s", "worker"}``."""
    t0 = time.perf_counter()
    log: list[str] = []
    result = {"status": "failed", "outputs": {}, "summary": None, "error": None, "traceback": None,
              "log": log, "worker": _worker_name(), "fingerprint": spec["fingerprint"]}
    _announce(result["worker"])
    with tempfile.TemporaryDirectory(prefix="boomfmi-case-") as tmp:
        tmp = Path(tmp)
        sources: dict[str, str] = {}
        paths = {"fit": [], "holdout": []}
        for f in spec["files"]:
            p = tmp / f["name"]
            p.write_bytes(f["csv"])
            if f["sidecar"] is not None:
                p.with_suffix(".json").write_bytes(f["sidecar"])
                sources[str(p.with_suffix(".json"))] = f["sidecar_source"]
            sources[str(p)] = f["source"]
            paths[f["role"]].append(p)
        out = tmp / "out"
        try:
            result["summary"] = _identify_and_diagnose(paths["fit"], paths["holdout"], out, spec.get("ssp"), log)
            result["status"] = "done"
        except Exception as e:            # reported with the case, never raised: the campaign goes on
            result["error"] = _restore(f"{type(e).__name__}: {e}", sources)
            result["traceback"] = _restore(traceback.format_exc(), sources)
        else:
            for p in sorted(out.iterdir()):
                if p.is_file() and not p.name.startswith("."):
                    data = p.read_bytes()
                    if p.suffix in (".json", ".html", ".ssv"):
                        data = _restore(data.decode(), sources, p.suffix).encode()
                    result["outputs"][p.name] = data
            result["summary"] = json.loads(_restore(json.dumps(result["summary"]), sources, ".json"))
            result["log"] = [_restore(line, sources) for line in log]
    result["wall_s"] = round(time.perf_counter() - t0, 3)
    return result


def _restore(text: str, sources: dict, kind: str = "") -> str:
    """``text`` with each temporary path replaced by the file's own (escaped for
    ``kind``: JSON strings, HTML or XML text)."""
    for tmp_path, source in sorted(sources.items(), key=lambda kv: -len(kv[0])):
        if kind == ".json":
            old, new = json.dumps(tmp_path)[1:-1], json.dumps(source)[1:-1]
        elif kind in (".html", ".ssv"):
            old, new = html.escape(tmp_path), html.escape(source)
        else:
            old, new = tmp_path, source
        text = text.replace(old, new)
    return text


def _identify_and_diagnose(fit, hold, out, ssp, log) -> dict:
    """The case's diagnosis (``diagnose.report.diagnose``, for the boom's recordings or
    the whole excavator's: per joint, :func:`_joints_summary`) and, for the boom's, its
    identification's outputs."""
    from ..diagnose import diagnose
    from ..identify import identify_recordings, write_outputs

    @functools.cache
    def baseline():               # identified once, where the diagnosis judges the recordings
        result, recs, _ = identify_recordings(fit, "fit")
        return result, recs
    doc = diagnose(fit, hold, out, workers=1, ssp=ssp, progress=log.append, baseline=baseline)
    if doc.get("kind") == "excavator":
        return _joints_summary(doc)
    summary = {"judgeable": doc["judgeable"], "verdict": doc["verdict"]}
    if not doc["judgeable"]:
        summary["reason"] = doc["reason"]
        return summary
    result, recs = baseline()
    write_outputs(result, recs, out / "params.json", holdout=hold)
    summary["params"] = {k: {"value": plain(float(e.value)), "ci95": plain([float(e.ci95[0]), float(e.ci95[1])]),
                             "unit": e.unit, "identified": identified(k, e, result.details)}
                         for k, e in result.params.items()}
    before = doc["baseline"]["nrmse_holdout"]
    summary.update(nrmse_holdout=before, gap_threshold=doc["gap_threshold"],
                   gap_beyond_noise=doc["gap_beyond_noise"], warnings=doc["baseline"]["warnings"],
                   where=doc["where"][:1])
    total = sum(before.values())
    summary["effects"] = {e["name"]: {"params": e["params"], "shrink": e["shrink"],
                                      "gain": round(total - sum(e["nrmse_holdout_after"].values()), 6)}
                          for e in doc["effects"] if not e.get("refused_by_load_fit")}
    conf = doc.get("confirmation") or {}
    summary["confirmation"] = {k: conf[k] for k in ("shrink", "reference_shrink", "agrees", "skipped", "error")
                               if k in conf}
    return summary


def _joints_summary(doc: dict) -> dict:
    """A case of the whole excavator's recordings (its diagnosis per joint, ``doc``),
    summarised as a boom case is: the baseline's per-joint parameters (``K_v_arm``, ...,
    ``payload``; those identification cannot tell marked so), the holdouts' NRMSE per
    joint and channel (``p_a_arm``), and each fitted effect on its joint
    (``piston_leakage@arm``, as the verdict names it) with the gap it removes on that
    joint's cut (``gain``) and that joint's threshold (``margin``, for the trends' flag
    rule)."""
    summary = {"kind": "excavator", "judgeable": doc.get("judgeable", True), "verdict": doc["verdict"]}
    if not summary["judgeable"]:
        summary["reason"] = doc.get("reason")
        return summary
    b = doc["baseline"]
    cannot = b.get("cannot_tell") or {}
    summary["params"] = {k: {"value": plain(float(v)), "ci95": plain(b["ci95"].get(k) or [None, None]),
                             "unit": b["units"].get(k), "identified": k not in cannot}
                         for k, v in b["params"].items()}
    summary["nrmse_holdout"] = {f"{c}_{j}": e for j, row in b["nrmse_holdout"].items() for c, e in row.items()}
    thresholds: dict = {}
    for w in doc["where"]:
        thresholds.setdefault(w["joint"], []).append(float(w["threshold"]))
    margin = {j: sum(v) / len(v) for j, v in thresholds.items()}
    summary.update(gap_threshold=round(max(margin.values(), default=0.0), 6), warnings=b.get("warnings", []),
                   where=doc["where"][:1])
    summary["effects"] = {}
    for e in doc["effects"]:          # best first per joint and cut: the first of a name on a joint
        key = f"{e['name']}@{e['joint']}"
        if key in summary["effects"] or e.get("gap_after") is None:
            continue
        summary["effects"][key] = {"params": e["params"], "shrink": e["shrink"],
                                   "gain": round(float(e["gap_before"]) - float(e["gap_after"]), 6),
                                   "margin": round(margin.get(e["joint"], 0.0), 6)}
    conf = doc.get("confirmation") or {}
    summary["confirmation"] = {k: conf[k] for k in ("shrink", "shrink_by_joint", "skipped", "error") if k in conf}
    return summary


def identified(name: str, estimate, details: dict) -> bool:
    """Whether identification says the data tell ``name``: F_s where its starts place
    it (``details["static_friction"]["identified"]``), any other where its 95 % interval
    is finite and narrower than half its value (``identify.fit``'s own rule; it warns
    of the others)."""
    if name == "F_s":
        return bool((details.get("static_friction") or {}).get("identified"))
    return estimate.tells


__all__ = ["CASE_VERSION", "case_spec", "CASE_STARTED", "run_case", "identified"]
