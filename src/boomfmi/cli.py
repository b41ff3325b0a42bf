"""The ``boomfmi`` command: a thin layer over the library.

    boomfmi simulate SSP --experiment paper_multistep|RUN.csv [--step 0.001] [--stop 9]
                         [--params params.ssv] [--set NAME=VALUE] [--replay | --rig udp://HOST:PORT]
                         [--algorithm gauss-seidel|jacobi] --out result.csv
    boomfmi rig serve --port P [--lockstep] [--record FILE] [--config rig.json] [--key-file K]
    boomfmi record --experiment paper_multistep --rig udp://127.0.0.1:P --out run.csv [--key-file K]
                                        (an excavator experiment, e.g. digging_cycle, through excavator_bridge.fmu)
    boomfmi identify RUN.csv [RUN.csv ...] [--method paper|fit] [--a-max] [--holdout H.csv] --out params.json
    boomfmi diagnose FIT.csv [FIT.csv ...] --holdout HOLD.csv [HOLD.csv ...] --out DIR
                                        (the boom's recordings, or the whole excavator's: per joint)
    boomfmi campaign MANIFEST.csv --out DIR [--scheduler ADDRESS] [--workers N]
    boomfmi fleet --machines 8 --weeks 6 --out DIR   a virtual fleet's recordings and manifest
    boomfmi view --replay RUN.csv [--model params.json [--write-run RUN.csv]] [--export OUT.mp4 [--start S]
                 [--history S]] | --live udp://HOST:PORT
                                        (--model: the excavator's identified machine beside its recording)
    boomfmi describe FMU [FMU ...]      the FMUs' interfaces as Markdown tables
    boomfmi recording import FILE --map "t=1:ms,u=2:V,..." [--delimiter D] [--skip-rows N] --out run.csv
    boomfmi bench friction FIT... (--holdout HOLD... | --split-strokes) --area A --out DIR [map options]
    boomfmi bench leak RUN... --volume V --out DIR [map options]
    boomfmi check FMU_DIR               validate every FMU and replay its reference result
"""
from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

from .link.protocol import LinkError


def _describe(args) -> int:
    from .describe import interface_table
    for path in args.fmus:
        print(interface_table(path))
    return 0


def _check(args) -> int:
    """Validate the FMUs in a folder and replay each one's reference result."""
    import numpy as np
    import pandas as pd
    from fmpy.validation import validate_fmu

    from .system.instance import model_description, run_table
    if not Path(args.fmu_dir).is_dir():
        raise ValueError(f"{args.fmu_dir}: no such folder")
    from .paths import references_dir
    references = Path(args.references) if args.references is not None else references_dir()
    if not references.is_dir():
        raise ValueError(f"--references {references}: no such folder")
    fmus = sorted(Path(args.fmu_dir).glob("*.fmu"))
    if not fmus:
        raise ValueError(f"{args.fmu_dir}: no .fmu files to check")
    failures = 0
    for fmu in fmus:
        try:
            model_description(fmu)
        except ValueError as e:
            print(f"{fmu.name:24s} INVALID: {e}")
            print(f"boomfmi check: {e}", file=sys.stderr)
            failures += 1
            continue
        problems = validate_fmu(str(fmu))
        status = "valid" if not problems else "INVALID: " + "; ".join(problems)
        ref_dir = references / fmu.stem
        in_csv, ref_csv = ref_dir / f"{fmu.stem}_in.csv", ref_dir / f"{fmu.stem}_ref.csv"
        if in_csv.is_file() and ref_csv.is_file():
            got = run_table(fmu, pd.read_csv(in_csv))
            want = pd.read_csv(ref_csv)
            err = max(float(np.max(np.abs(got[c] - want[c]) / (np.abs(want[c]) + 1e-12)))
                      for c in want.columns)
            status += f", reference result max rel. error {err:.1e}"
            failures += err > 1e-9
        failures += bool(problems)
        print(f"{fmu.name:24s} {status}")
    return 1 if failures else 0


def _port(text: str) -> int:
    """An argparse type: a port number, 0 to 65535."""
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a port number") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"{port} is not a port: 0 to 65535")
    return port


def _positive(text: str) -> float:
    """An argparse type: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"{text} must be a finite number > 0")
    return value


def _watchdog(text: str) -> float:
    """An argparse type: the rig's watchdog, > 0 and at most ``rig.server.MAX_WATCHDOG`` s."""
    from .rig.server import MAX_WATCHDOG
    value = _positive(text)
    if value > MAX_WATCHDOG:
        raise argparse.ArgumentTypeError(f"{text} s is beyond the longest watchdog, {MAX_WATCHDOG:g} s: "
                                         f"the fail-safe would in effect be off")
    return value


def _value(text: str):
    """A ``--set`` value: an integer, a real, true/false, or else a string."""
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(text.lower(), text)


def _not_inputs(outputs, files=(), recordings=()) -> None:
    """Refuse (``outputs.OutputError``) an output that is one of the command's input
    ``files`` or ``recordings`` (or a recording's sidecar), by name or through links."""
    from .outputs import check_not_inputs
    from .recording import recording_inputs
    check_not_inputs(outputs, [*(Path(f) for f in files if f), *recording_inputs(recordings)])


def _simulate(args) -> int:
    from .simulate import run_experiment
    if args.out.is_dir():
        raise IsADirectoryError(f"{args.out}: Is a directory; --out names the CSV file to write")
    experiment = Path(args.experiment)
    _not_inputs([args.out], [args.ssp, *args.params, args.key_file],
                [experiment] if experiment.suffix.lower() == ".csv" or experiment.exists() else [])
    given = {}
    for item in args.set:
        name, eq, value = item.partition("=")
        if not eq or "." not in name:
            raise ValueError(f"--set {item!r}: expected COMPONENT.PARAMETER=VALUE")
        given[name] = _value(value)
    if args.replay:
        if not args.experiment.lower().endswith(".csv"):
            raise ValueError("--replay plays the experiment's recording through the hardware bridge: "
                             "give --experiment RUN.csv")
        from .simulate import replay_parameters
        given = {**replay_parameters(args.experiment), **given}
    if args.rig:
        given.update({"hardware_bridge.mode": "udp", "hardware_bridge.rig": args.rig})
    view_key = _view_key(args.key_file, "--view", "the stream") if args.view else None
    if args.key_file and not args.view:
        raise ValueError("--key-file signs the --view stream: give --view too (the hardware bridge's key: "
                         "--set hardware_bridge.key_file=K or $BOOMFMI_LINK_KEY)")
    result = run_experiment(args.ssp, args.experiment, args.step, args.stop, args.algorithm,
                            [*args.params, given] if given else args.params, progress=True,
                            view=args.view, view_key=view_key)
    from .outputs import OutputSet
    with OutputSet(args.out.parent) as files:          # an interrupt leaves the old file whole; locked
        result.to_csv(files.path(args.out.name), index=False, float_format="%.10g")
    last = result.iloc[-1]
    if "x" not in result:                              # the whole excavator's columns
        from .physics import JOINTS
        print(f"wrote {args.out}: {len(result)} rows, t = {result.t.iloc[0]:g} to {last.t:g} s; at the end "
              + ", ".join(f"x_{j} = {1000 * last[f'x_{j}']:.2f} mm" for j in JOINTS))
        return 0
    print(f"wrote {args.out}: {len(result)} rows, t = {result.t.iloc[0]:g} to {last.t:g} s; "
          f"at the end x = {1000 * last.x:.2f} mm, p_a = {last.p_a / 1e5:.3f} bar, "
          f"p_b = {last.p_b / 1e5:.3f} bar (gauge)")
    return 0


def _view_key(key_file, option: str, what: str) -> bytes:
    """The link key that signs (``simulate --view``) or checks (``view --live``) the
    live stream; LinkError naming the options when there is none."""
    from .link.protocol import KEY_ENV, load_key
    try:
        return load_key(key_file)
    except LinkError as e:
        raise LinkError(f"{option} authenticates {what} with the rig link's key (--key-file K or "
                        f"${KEY_ENV}): {e}") from None


def _view(args) -> int:
    if args.key_file and not args.live:
        raise ValueError("--key-file checks the --live stream: give --live udp://HOST:PORT")
    if args.history is not None and not args.export:
        raise ValueError("--history is the plots' past before --start in an --export video: give --export too")
    if args.write_run and not args.model:
        raise ValueError("--write-run writes the run file of --replay's recording with the identified machine: "
                         "give --model params.json too")
    if args.model:
        if not args.replay:
            raise ValueError("--model simulates the identified machine on a recording: give --replay "
                             "RECORDING.csv (the excavator's)")
        import tempfile
        from .identify import write_run
        with tempfile.TemporaryDirectory(prefix="boomfmi-run-") as tmp:
            out = args.write_run or Path(tmp) / f"{args.replay.stem}_run.csv"
            run = write_run(args.replay, args.model, out, progress=_progress("view"))
            if args.write_run:
                print(f"wrote {run}: the machine identified in {args.model} beside {args.replay}, "
                      f"f_tip_est and its interval")
                if not args.export:
                    return 0
            args.replay = run
            return _view_run(args)
    return _view_run(args)


def _view_run(args) -> int:
    """``view`` on a run file (``--replay``) or live: the page, or with ``--export`` a video."""
    if args.export:
        if not args.replay:
            raise ValueError("--export renders a run file: give --replay RUN.csv")
        from .view.export import export
        path, n = export(args.replay, args.export, fps=args.fps, start=args.start, stop=args.stop,
                         size=args.size, history=args.history)
        print(f"wrote {path}: {n} frames at {args.fps:g} per second")
        return 0
    from .view.server import serve

    def ready(url: str) -> None:
        what = f"replaying {args.replay}" if args.replay else f"live from {args.live}"
        print(f"view on {url} ({what}); Ctrl-C stops it", flush=True)

    key = _view_key(args.key_file, "--live", "the stream") if args.live else None
    serve(args.replay, args.live, args.host, args.port, ready, key=key, origins=args.allow_origin)
    return 0


def _rig_serve(args) -> int:
    from .link.protocol import load_key
    from .rig import make_rig
    from .rig.server import realtime_priority, serve
    if args.record:
        _not_inputs([args.record], [args.config, args.key_file])
    key = load_key(args.key_file)
    plant = make_rig(args.config)       # the boom's, or the excavator's ("machine": "excavator")
    if args.priority:
        print(realtime_priority(args.priority), flush=True)
    mode = "lockstep" if args.lockstep else "real time, 1 kHz"

    def ready(port: int) -> None:
        print(f"rig listening on udp://{args.host}:{port} ({mode}); watchdog {args.watchdog * 1e3:g} ms"
              + (f"; recording to {args.record}" if args.record else ""), flush=True)

    counters = serve(plant, key, args.port, args.host, args.lockstep, args.record, args.watchdog, ready)
    print(f"rig stopped: {counters.summary()}", flush=True)
    return 0


def _record(args) -> int:
    from .record import record_experiment
    command_csv = [Path(args.experiment)] if args.experiment.lower().endswith(".csv") else []   # a command CSV
    _not_inputs([args.out], [args.fmu, args.key_file, *command_csv])
    stats = record_experiment(args.fmu, args.rig, args.out, args.experiment, args.step, args.stop,
                              args.key_file, args.timeout, args.retries, args.loss_budget, _machine(args))
    print(f"wrote {args.out}: {stats['rows']} rows, {stats['lost_packets']} answers lost")
    return 0


def _identify(args) -> int:
    from .recording import common_kind
    if args.out.is_dir():
        raise IsADirectoryError(f"{args.out}: is a folder; --out names params.json (params.ssv and params.png "
                                f"go beside it)")
    _not_inputs([args.out, args.out.with_suffix(".ssv"), args.out.with_suffix(".png")],
                recordings=[*args.recordings, *args.holdout])
    common_kind([*args.recordings, *args.holdout])      # the boom's or the excavator's: a mix is refused
    from .identify import identify_recordings, summary_lines, write_outputs
    say = _progress("identify")
    result, recs, _ = identify_recordings(args.recordings, args.method, args.a_max, args.cutoff, args.eq13,
                                          machine=_machine(args), progress=say)
    doc = write_outputs(result, recs, args.out, args.holdout, progress=say)
    for line in summary_lines(doc):
        print(line)
    print("wrote " + ", ".join(doc["written"]))
    return 0


def _diagnose(args) -> int:
    from .diagnose.report import OUTPUTS
    from .recording import common_kind
    _not_inputs([args.out / name for name in OUTPUTS], [args.ssp], [*args.recordings, *args.holdout])
    if args.propose is not None:
        _not_inputs([args.propose], [args.ssp], [*args.recordings, *args.holdout])
        from .outputs import OutputError
        clash = [args.out / n for n in OUTPUTS if os.path.realpath(args.out / n) == os.path.realpath(args.propose)]
        if clash:
            raise OutputError(f"--propose {args.propose}: that is the diagnosis' own {clash[0]}; give the "
                              f"command CSV another name")
    common_kind([*args.recordings, *args.holdout])      # the boom's or the excavator's: a mix is refused
    from .diagnose import diagnose
    doc = diagnose(args.recordings, args.holdout, args.out, ssp=args.ssp,
                   progress=lambda text: print(f"diagnose: {text}", file=sys.stderr, flush=True),
                   machine=_machine(args), propose=args.propose)
    if doc.get("kind") == "excavator":                  # found per joint: each joint's gap and finding
        from .diagnose.report import summary_lines
        for line in summary_lines(doc):
            print(line)
        print(f"wrote {args.out}/diagnosis.json and {args.out}/report.html")
        return 0
    for w in (doc.get("baseline") or {}).get("warnings", []):
        print(f"warning (baseline): {w}")
    if not doc["judgeable"]:
        print(f"cannot judge: {doc['reason']}")
    else:
        b = doc["baseline"]["nrmse_holdout"]
        print("baseline holdout NRMSE: " + ", ".join(f"{k} {100 * v:.2f} %" for k, v in b.items()))
        if doc["where"]:
            w = doc["where"][0]
            print(f"the gap lies mostly in {w['channel']} during {w['regime']} ({w['subsystem']}, "
                  f"{100 * w['share']:.0f} % of it)")
        for c in doc["effects"][:3]:
            print(f"  {c['name']}: shrink {c['shrink']:.2f}, score {c['score']:.2f}")
        print(f"verdict: {doc['verdict']}")
        c = doc.get("confirmation") or {}
        if "shrink" in c:
            print(f"through the FMUs ({c['ssp']}): shrink {c['shrink']:.2f} against the reference's "
                  f"{c.get('reference_shrink', float('nan')):.2f}, {'agreeing' if c.get('agrees') else 'DISAGREEING'}")
        elif "skipped" in c or "error" in c:
            print(f"not confirmed through the FMUs: {c.get('skipped') or c.get('error')}")
    from .diagnose.report import action_sentence
    print(action_sentence(doc))
    n = doc.get("next_experiment")
    if n:
        print(f"next experiment: {n['design']} {n['params']} tells {n['hypotheses'][0]} from {n['hypotheses'][1]} "
              f"(expected log-likelihood ratio {n['separation']:.3g})" + (f"; its command: {n['csv']}" if n.get("csv")
                                                                           else ""))
    elif args.propose is not None:
        print(f"no experiment proposed, {args.propose} not written: no two explanations to tell apart")
    print(f"wrote {args.out}/diagnosis.json and {args.out}/report.html")
    return 0


#: Run in each worker process of campaign's local cluster as it starts (Dask's worker
#: preload, as script text): Ctrl-C reaches the whole process group, and only this
#: process answers it (it cancels the cases, closes the cluster and says "interrupted");
#: a worker that took it too would print its own KeyboardInterrupt traceback.  And a
#: worker whose scheduler went first (this process, interrupted, on a loaded machine)
#: does not log its failed heartbeat with a traceback: the campaign is ending, and the
#: cases' own records say what became of them.
_WORKER_IGNORES_SIGINT = (
    "import logging, signal\n"
    "signal.signal(signal.SIGINT, signal.SIG_IGN)\n"
    "class _SchedulerGone(logging.Filter):\n"
    "    def filter(self, record):\n"
    "        return 'communicate with scheduler during heartbeat' not in record.getMessage()\n"
    "logging.getLogger('distributed.worker').addFilter(_SchedulerGone())\n")


def _campaign(args) -> int:
    import dask

    from .campaign import run_campaign
    with dask.config.set({"distributed.worker.preload": [_WORKER_IGNORES_SIGINT]}):
        doc = run_campaign(args.manifest, args.out, scheduler=args.scheduler, workers=args.workers, ssp=args.ssp,
                           progress=lambda text: print(text, end="", file=sys.stderr, flush=True))
    run = doc["run"]
    for m, info in doc["machines"].items():
        last = info["last"]
        verdict = (f"FAILED ({last['error']})" if last["status"] != "done" else
                   f"verdict {last['verdict']}" if last["judgeable"] else "not judgeable")
        flags = "; ".join(f"{f['name']} {f['direction']} from {f['date']}" for f in info["flags"]) or "no flag"
        print(f"{m}: last {last['date']} {verdict}; {flags}")
    print(f"{run['cases']} cases: {run['ran']} run, {run['resumed']} done before, {run['failed']} failed "
          f"({run['wall_s']:.0f} s on {run['worker_threads']} worker thread(s) at {run['address']})")
    for worker, why in (run.get("workers_lost") or {}).items():
        print(f"worker lost: {worker} ({why}); the cases it held went back to the scheduler (their attempts: campaign.json)")
    print(f"wrote {args.out}/campaign.json, {args.out}/campaign.html and {args.out}/cases/")
    return 1 if run["failed"] else 0


def _fleet(args) -> int:
    from .campaign.fleet import make_fleet
    manifest = make_fleet(args.out, args.machines, args.weeks, args.seed, args.duration, args.workers,
                          progress=_progress("fleet"))
    print(f"wrote {manifest} ({args.machines} machines x {args.weeks} weeks) and {args.out}/truth.json")
    return 0


def _separators(values, option: str):
    """``--decimal``/``--thousands`` values: one character for every column, or
    NAME=CHAR for some (repeatable)."""
    if not values:
        return None
    named = [v for v in values if "=" in v and len(v) > 1]
    if not named:
        if len(values) > 1:
            raise ValueError(f"{option} given {len(values)} times: give one character, or NAME=CHAR per column")
        return values[0]
    if len(named) != len(values):
        raise ValueError(f"{option}: give one character for every column or NAME=CHAR for some, not both")
    return dict(v.split("=", 1) for v in named)


def _read_options(args) -> dict:
    """The foreign-file read options of the map arguments (a --preset's, overridden)."""
    from .foreign import read_options
    return read_options(args.preset, map=args.map, delimiter=args.delimiter, skip_rows=args.skip_rows,
                        header=True if args.header else None, decimal=_separators(args.decimal, "--decimal"),
                        thousands=_separators(args.thousands, "--thousands"), encoding=args.encoding)


def _add_machine_option(p, what: str) -> None:
    p.add_argument("--machine", type=Path, metavar="FILE",
                   help=f"your machine's file (boomfmi machine init), {what}")


def _add_map_options(p) -> None:
    from .foreign import PRESETS
    p.add_argument("--map", help="the columns: NAME=COLUMN:UNIT,... with COLUMN a 1-based number or (with "
                                 "--header) a header name and UNIT any pint unit, e.g. "
                                 "\"t=1:ms,x=5:mm,p_gauge=6:bar,F=7:N\"; pressures say p_gauge or p_abs")
    p.add_argument("--delimiter", help="tab (default), comma, semicolon, space, whitespace, or one character")
    p.add_argument("--skip-rows", type=int, help="lines to drop at the top (start-up samples, a preamble)")
    p.add_argument("--header", action="store_true", help="the first line after the skipped ones names the columns")
    p.add_argument("--decimal", action="append", metavar="CHAR|NAME=CHAR",
                   help="decimal mark (default '.', or ',' where --thousands is '.'); NAME=CHAR for one column")
    p.add_argument("--thousands", action="append", metavar="CHAR|NAME=CHAR",
                   help="thousands separator (default none); NAME=CHAR for one column, e.g. t=.")
    p.add_argument("--encoding", help="the file's text encoding (default utf-8)")
    p.add_argument("--preset", choices=sorted(PRESETS),
                   help="a known source's map and layout (zillen2021: the friction tests, zillen2021-leak: the "
                        "leak-down tests of Zillen, Vallery, Smit 2021); the options above override it")


def _recording_import(args) -> int:
    from .foreign import import_recording
    machine = _machine(args)
    out = import_recording(args.file, args.out, _read_options(args), machine=machine)
    if machine is None:
        print("recording import: no --machine: the recording gets no sidecar, and identify and diagnose will "
              "assume the reference rig (describe yours with: boomfmi machine init --out machine.json)",
              file=sys.stderr)
    from .recording import read_recording
    rec = read_recording(out)
    print(f"wrote {out}: {len(rec.data)} rows, columns {', '.join(rec.data.columns)}")
    return 0


def _machine(args):
    """The ``--machine FILE`` of a command, read and checked before anything else
    (:func:`main`); None without one."""
    if getattr(args, "machine", None) is None:
        return None
    if getattr(args, "machine_read", None) is None:
        from .machine import read_machine
        args.machine_read = read_machine(args.machine)
    return args.machine_read


def _machine_init(args) -> int:
    from ._json import dumps
    from .machine import machine_document
    from .outputs import OutputSet
    if args.out.exists():
        raise FileExistsError(f"{args.out}: exists; edit it, or choose another --out")
    doc = machine_document(args.kind, args.name or "")
    with OutputSet(args.out.parent) as files:
        files.path(args.out.name).write_text(dumps(doc, indent=2) + "\n")
    print(f"wrote {args.out}: the {'reference rig' if args.kind == 'boom' else 'excavator of excavator.md'}, "
          f"{len(doc['rig'])} values (SI units, or any unit as text: \"63 mm\"); edit it to your machine and "
          f"give it to identify, diagnose, record and recording import with --machine {args.out}")
    return 0


def _machine_check(args) -> int:
    from .machine import read_machine, units_of
    m = read_machine(args.file)
    units = units_of(m.kind)
    print(f"{args.file}: {'an' if m.kind == 'excavator' else 'a'} {m.kind}{f' ({m.name})' if m.name else ''}, "
          f"{len(m.rig)} values, within the physics' bounds")
    for k, v in m.rig.items():
        print(f"  {k} = {v:.6g} {units[k]}")
    return 0


def _progress(command: str):
    return lambda text: print(f"{command}: {text}", file=sys.stderr, flush=True)


def _bench_friction(args) -> int:
    from .bench import quantity, run_friction
    area = quantity(args.area, "m**2", "--area")
    doc = run_friction(args.fit, args.holdout, area, _read_options(args), args.out, split=args.split_strokes,
                       smooth=args.smooth, n_boot=args.n_boot, progress=_progress("bench friction"))
    for law, L in doc["laws"].items():
        P = L["parameters"]
        extra = (f", F_d(p) = {P['F_d0']:.3g} N + {P['c_d'] * 1e5:.3g} N/bar * p" if law == "pressure" else "")
        print(f"{law:9s} holdout RMSE {L['rmse_holdout_N']:.3f} N (fit {L['rmse_fit_N']:.3f} N); "
              f"A_eff = {P['A_eff'] * 1e6:.2f} mm^2, F_0 = {P['F_0']:.2f} N{extra}")
    for w in doc["warnings"]:
        print(f"warning: {w}")
    print(f"chosen: {doc['chosen']}")
    print(f"wrote {args.out}/friction.json, friction.html, friction_velocity.png, friction_pressure.png")
    return 0


def _bench_leak(args) -> int:
    from .bench import parse_pressure, quantity, run_leak
    volume = quantity(args.volume, "m**3", "--volume")
    p_start = parse_pressure(args.p_start) if args.p_start else None
    doc = run_leak(args.runs, volume, _read_options(args), args.out, p_start=p_start, start=args.start,
                   progress=_progress("bench leak"))
    for r in doc["runs"]:
        size = r["size"]
        value = (f"A = {size['value'] * 1e6:.3g} mm^2 [{size['ci95'][0] * 1e6:.3g}, {size['ci95'][1] * 1e6:.3g}]"
                 if size["name"] == "A" else
                 f"C = {size['value']:.3g} kg/(s Pa) [{size['ci95'][0]:.3g}, {size['ci95'][1]:.3g}]")
        print(f"{r['file']}: {r['chosen']} ({r['laminar_vs_orifice']}), {value}, drop {1e3 * r['drop_bar']:.1f} mbar "
              f"in {r['duration_s']:.0f} s")
    print(f"wrote {args.out}/leak.json, leak.png")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The whole command line's parser, built without running anything (tests/test_readme.py parses
    every command of the README with it): the options of every command, then each command's own
    parser from its builder (``COMMANDS``: ``_simulate_parser(sub)``, ...)."""
    parser = argparse.ArgumentParser(prog="boomfmi", description=__doc__.splitlines()[0])
    parser.add_argument("--effects", type=Path, action="append", default=[], metavar="FILE",
                        help="a Python file of your own effects (a plug-in: effects(catalogue), rig_effects(truth)) "
                             "for every command; repeatable (installed plug-ins, entry point boomfmi.effects, "
                             "load by themselves)")
    sub = parser.add_subparsers(dest="command", required=True)
    for add in COMMANDS:
        add(sub)
    return parser


def _simulate_parser(sub) -> None:
    """``boomfmi simulate``: an experiment on an SSP."""
    p = sub.add_parser("simulate", help="run an experiment on an SSP system, write a recording-format CSV")
    p.add_argument("ssp", type=Path, help="the system, e.g. build/excavator_boom.ssp")
    p.add_argument("--experiment", default="paper_multistep",
                   help="a named command profile (paper_multistep) or a recording whose u drives the valve")
    p.add_argument("--step", type=float, default=1e-3, help="communication step [s] (default 0.001)")
    p.add_argument("--stop", type=_positive, default=None, help="stop time [s] (default: the experiment's end)")
    p.add_argument("--params", type=Path, action="append", default=[],
                   help="a parameter set (.ssv, names like valve.A_max) applied after the SSP's own; repeatable")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="set one parameter, e.g. force_estimator.method=position_error (after --params)")
    link = p.add_mutually_exclusive_group()
    link.add_argument("--replay", action="store_true",
                      help="teleoperation: the hardware bridge replays the experiment's recording")
    link.add_argument("--rig", help="teleoperation: the hardware bridge talks to the rig at udp://HOST:PORT "
                                    "(a lockstep or real-time `boomfmi rig serve`)")
    p.add_argument("--algorithm", choices=("gauss-seidel", "jacobi"), default="gauss-seidel")
    p.add_argument("--view", metavar="udp://HOST:PORT",
                   help="stream the run to `boomfmi view --live` listening there (60 samples per second), "
                        "signed with the link key")
    p.add_argument("--key-file", help="--view: file holding the shared link key that signs the stream "
                                      "(default: $BOOMFMI_LINK_KEY)")
    p.add_argument("--out", type=Path, required=True, help="output CSV (recording columns plus x, v)")
    p.set_defaults(run=_simulate)


def _rig_parser(sub) -> None:
    """``boomfmi rig``: the virtual rig."""
    p = sub.add_parser("rig", help="the virtual rig")
    rig_sub = p.add_subparsers(dest="rig_command", required=True)
    p = rig_sub.add_parser("serve", help="simulate the machine behind an authenticated UDP link")
    p.add_argument("--port", type=_port, required=True, help="UDP port (0: any free port, printed)")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default: loopback only)")
    p.add_argument("--lockstep", action="store_true", help="advance one sample per command instead of real time")
    p.add_argument("--record", type=Path, help="write every measured sample to this recording")
    p.add_argument("--config", type=Path, help="JSON: effects, noise, contact, parameters (default: reference rig, noise on)")
    p.add_argument("--key-file", help="file holding the shared link key (default: $BOOMFMI_LINK_KEY)")
    p.add_argument("--watchdog", type=_watchdog, default=0.05,
                   help="fail-safe after this long without a command [s], at most 10 (default 0.05)")
    p.add_argument("--priority", type=int, default=0, metavar="N",
                   help="run under the real-time scheduler (SCHED_FIFO) at priority N, 1 to 99 (needs the "
                        "right: root or CAP_SYS_NICE); 0: the normal scheduler (default)")
    p.set_defaults(run=_rig_serve)


def _record_parser(sub) -> None:
    """``boomfmi record``: an experiment on a rig through the hardware bridge."""
    p = sub.add_parser("record", help="run an experiment on a rig through the hardware bridge, write a recording")
    p.add_argument("--experiment", default="paper_multistep")
    p.add_argument("--rig", required=True, help="udp://HOST:PORT")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--key-file", help="file holding the shared link key (default: $BOOMFMI_LINK_KEY)")
    p.add_argument("--fmu", type=Path, default=None,
                   help="the bridge FMU (default: the checkout's build/fmus/hardware_bridge.fmu, or under "
                        "$BOOMFMI_BUILD, from any working directory; for an excavator experiment such as "
                        "digging_cycle, build/fmus/excavator_bridge.fmu)")
    p.add_argument("--step", type=float, default=1e-3)
    p.add_argument("--stop", type=float, default=None)
    p.add_argument("--timeout", type=float, default=0.05, help="longest wait for the rig's answer per step [s]")
    p.add_argument("--retries", type=int, default=2)
    p.add_argument("--loss-budget", type=int, default=20, help="consecutive lost answers before giving up")
    _add_machine_option(p, "written into the recording's sidecar")
    p.set_defaults(run=_record)


def _identify_parser(sub) -> None:
    """``boomfmi identify``: identification."""
    p = sub.add_parser("identify", help="identify the model's parameters from recordings (the boom's, or the whole "
                                        "excavator's: each cylinder's K_v, F_s, F_d and the payload)")
    p.add_argument("recordings", nargs="+", type=Path)
    p.add_argument("--method", choices=("fit", "paper"), default="fit",
                   help="fit: least squares on all samples, with intervals (default); paper: Eq. 13 to 17")
    p.add_argument("--a-max", action="store_true", help="also identify the valve's A_max")
    p.add_argument("--holdout", type=Path, action="append", default=[],
                   help="a recording not used for fitting, to report the model's error on")
    p.add_argument("--cutoff", type=float, default=25.0, help="low-pass cut-off [Hz]")
    p.add_argument("--eq13", choices=("printed", "derived"), default="printed",
                   help="paper method: Eq. 13 as printed, or as derived from the force balances")
    p.add_argument("--out", type=Path, required=True, help="params.json (params.ssv and params.png go beside it)")
    _add_machine_option(p, "the recordings are of (default: their sidecars, else the reference rig)")
    p.set_defaults(run=_identify)


def _diagnose_parser(sub) -> None:
    """``boomfmi diagnose``: diagnosis."""
    p = sub.add_parser("diagnose", help="where the model and the machine disagree, and which effect explains it "
                                        "(for the whole excavator's recordings: which joint, and which effect)")
    p.add_argument("recordings", nargs="+", type=Path, help="FIT recordings: identify the baseline, fit the effects")
    p.add_argument("--holdout", type=Path, nargs="+", required=True,
                   help="HOLD recordings, never fitted on: every figure of shrink is measured on them")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--ssp", type=Path, default=None,
                   help="the boom's SSP for confirming the verdict through the FMUs (default: build/excavator_boom.ssp)")
    p.add_argument("--propose", type=Path, default=None, metavar="FILE",
                   help="write the command CSV (t, u) of the experiment that best tells the two most probable "
                        "explanations apart, for `boomfmi record --experiment FILE` (the report proposes one by "
                        "itself where they are within a factor of 10, or where the verdict is unexplained)")
    _add_machine_option(p, "the recordings are of (default: their sidecars, else the reference rig)")
    p.set_defaults(run=_diagnose)


def _campaign_parser(sub) -> None:
    """``boomfmi campaign``: a campaign on Dask."""
    p = sub.add_parser("campaign", help="identify and diagnose many machines and dates on Dask; trends and flags")
    p.add_argument("manifest", type=Path, help="CSV: machine, date, role (fit or holdout), recording[, sidecar]")
    p.add_argument("--out", type=Path, required=True,
                   help="output folder: campaign.json, campaign.html, cases/<machine>/<date>/ (a re-run resumes)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="a running Dask scheduler, e.g. tcp://10.0.0.5:8786 (default: a local cluster)")
    p.add_argument("--workers", type=int, default=None,
                   help="worker processes of the local cluster, one thread each (default: one per core)")
    p.add_argument("--ssp", type=Path, default=None,
                   help="the boom's SSP for each verdict's confirmation through the FMUs "
                        "(default: build/excavator_boom.ssp)")
    p.set_defaults(run=_campaign)


def _fleet_parser(sub) -> None:
    """``boomfmi fleet``: a virtual fleet."""
    p = sub.add_parser("fleet", help="a virtual fleet (the virtual rig, known changes) for campaign's demo")
    p.add_argument("--machines", type=int, default=8)
    p.add_argument("--weeks", type=int, default=6)
    p.add_argument("--seed", type=int, default=20)
    p.add_argument("--duration", type=_positive, default=7.0, help="each experiment's length [s] (default 7)")
    p.add_argument("--workers", type=int, default=None, help="processes recording (default: one per core)")
    p.add_argument("--out", type=Path, required=True, help="folder: recordings, manifest.csv, truth.json")
    p.set_defaults(run=_fleet)


def _view_parser(sub) -> None:
    """``boomfmi view``: the virtual view."""
    p = sub.add_parser("view", help="the virtual boom or whole excavator in a browser, from a run file or live; "
                                    "or a video of either")
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--replay", type=Path, metavar="RUN.csv",
                        help="a recording, the boom's or the excavator's (its kind read from its columns), or "
                             "a teleoperation run from `boomfmi simulate` (model beside machine)")
    source.add_argument("--live", metavar="udp://HOST:PORT",
                        help="listen there for a co-simulation's samples (`boomfmi simulate --view`, "
                             "signed with the same link key)")
    p.add_argument("--key-file", help="--live: file holding the shared link key that checks the stream "
                                      "(default: $BOOMFMI_LINK_KEY)")
    p.add_argument("--allow-origin", action="append", default=[], metavar="http://HOST:PORT",
                   help="also serve pages of this origin (and requests naming HOST:PORT), e.g. through a "
                        "tunnel or another address; by default only 127.0.0.1, localhost and [::1] at --port")
    p.add_argument("--host", default="127.0.0.1", help="address of the page (default: loopback only)")
    p.add_argument("--port", type=_port, default=8765, help="port of the page (0: any free port, printed)")
    p.add_argument("--export", type=Path, metavar="OUT.mp4|OUT.gif",
                   help="render the replay to a video instead of serving the page")
    p.add_argument("--fps", type=float, default=25.0, help="--export: frames per second (default 25)")
    p.add_argument("--start", type=float, default=None, help="--export: from this time [s]")
    p.add_argument("--stop", type=float, default=None, help="--export: to this time [s]")
    p.add_argument("--size", default="1280x720", help="--export: WIDTHxHEIGHT in pixels (default 1280x720)")
    p.add_argument("--history", type=float, default=None, metavar="SECONDS",
                   help="--export: the plots' past before --start, as the page shows it (default: the plots' "
                        "10 s window; 0: none)")
    p.add_argument("--model", type=Path, metavar="params.json",
                   help="with --replay RECORDING.csv (the excavator's): simulate the machine `boomfmi identify` "
                        "wrote there on the recording's commands, beside the machine, with the estimated tip "
                        "force f_tip_est and its interval, and view (or --export) that run")
    p.add_argument("--write-run", type=Path, metavar="RUN.csv",
                   help="with --model: write that run file here (then stop, unless --export) for a later "
                        "`boomfmi view --replay RUN.csv`")
    p.set_defaults(run=_view)


def _recording_parser(sub) -> None:
    """``boomfmi recording``: recordings."""
    p = sub.add_parser("recording", help="recordings: import a foreign measurement file")
    rec_sub = p.add_subparsers(dest="recording_command", required=True)
    p = rec_sub.add_parser("import", help="convert a delimited text file into the recording format, by a column map")
    p.add_argument("file", type=Path)
    _add_map_options(p)
    p.add_argument("--out", type=Path, required=True, help="the recording to write (CSV)")
    _add_machine_option(p, "written as the recording's sidecar (its P_atm converts gauge and absolute pressures)")
    p.set_defaults(run=_recording_import)


def _machine_parser(sub) -> None:
    """``boomfmi machine``: the machine file."""
    p = sub.add_parser("machine", help="describe your machine in one file (for --machine)")
    m_sub = p.add_subparsers(dest="machine_command", required=True)
    p = m_sub.add_parser("init", help="write a machine file at the reference's values, for you to edit")
    p.add_argument("--kind", choices=("boom", "excavator"), default="boom",
                   help="boom: the paper's one-joint rig (default); excavator: the whole four-joint machine")
    p.add_argument("--name", help="the machine's name (free text)")
    p.add_argument("--out", type=Path, required=True, help="the machine file to write (JSON)")
    p.set_defaults(run=_machine_init)
    p = m_sub.add_parser("check", help="read and check a machine file; print its values in SI units")
    p.add_argument("file", type=Path)
    p.set_defaults(run=_machine_check)


def _bench_parser(sub) -> None:
    """``boomfmi bench``: the test bench."""
    p = sub.add_parser("bench", help="the test bench: friction and leak-down tests of a cylinder")
    bench_sub = p.add_subparsers(dest="bench_command", required=True)
    p = bench_sub.add_parser("friction", help="fit the friction laws (eq9, stribeck, pressure), score them on "
                                              "held-out tests, choose one")
    p.add_argument("fit", nargs="+", type=Path, help="FIT files: friction tests (t, x, p, F) the laws are fitted on")
    p.add_argument("--holdout", nargs="+", type=Path, default=[], help="HOLD files, never fitted on: the score")
    p.add_argument("--split-strokes", action="store_true",
                   help="fit on the first half of each FIT file's strokes, score also on the second half")
    p.add_argument("--area", required=True, help="the piston's nominal area: m^2, or with a unit ('490.9 mm^2')")
    p.add_argument("--smooth", type=_positive, default=None, help="bandwidth of the velocity's smoothing [s] "
                                                                  "(default 0.03)")
    p.add_argument("--n-boot", type=int, default=None, help="bootstrap replicates of the intervals (default 200)")
    _add_map_options(p)
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.set_defaults(run=_bench_friction)
    p = bench_sub.add_parser("leak", help="fit leak-down curves with the laminar and orifice laws, with and without "
                                          "thermal relaxation")
    p.add_argument("runs", nargs="+", type=Path, help="leak-down runs (t and p_gauge, p_abs, or dp with --p-start)")
    p.add_argument("--volume", required=True, help="the chamber's volume: m^3, or with a unit ('0.5 L')")
    p.add_argument("--p-start", help="for a map with dp (a pressure change): the gauge pressure at the first "
                                     "sample, with its unit ('7.5 bar')")
    p.add_argument("--start", type=float, default=None,
                   help="the time the chamber was closed, in the file's time [s] (default: found)")
    _add_map_options(p)
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.set_defaults(run=_bench_leak)


def _describe_parser(sub) -> None:
    """``boomfmi describe``: FMU interfaces."""
    p = sub.add_parser("describe", help="print FMU interfaces as Markdown tables")
    p.add_argument("fmus", nargs="+", type=Path)
    p.set_defaults(run=_describe)


def _check_parser(sub) -> None:
    """``boomfmi check``: FMU validation."""
    p = sub.add_parser("check", help="validate FMUs and replay their reference results")
    p.add_argument("fmu_dir", type=Path)
    p.add_argument("--references", type=Path, default=None,
                   help="folder with <name>/<name>_in.csv and _ref.csv (default: the checkout's fmus/, "
                        "whatever the working directory)")
    p.set_defaults(run=_check)


#: One parser builder per command, in the order ``boomfmi --help`` lists them.
COMMANDS = (_simulate_parser, _rig_parser, _record_parser, _identify_parser, _diagnose_parser, _campaign_parser,
            _fleet_parser, _view_parser, _recording_parser, _machine_parser, _bench_parser, _describe_parser,
            _check_parser)


def _effects(args) -> None:
    """``--effects FILE``: loaded here and named in ``$BOOMFMI_EFFECTS`` for the processes
    a command starts (Dask workers, FMU builds)."""
    if not args.effects:
        return
    from .model.catalogue import EFFECTS_ENV, load_plugins
    files = [str(f.resolve()) for f in args.effects]
    os.environ[EFFECTS_ENV] = os.pathsep.join([*filter(None, [os.environ.get(EFFECTS_ENV)]), *files])
    load_plugins(files)


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        _effects(args)                   # the user's effect plug-ins, before anything reads the catalogue
        _machine(args)                   # a machine file is checked before any work
        return args.run(args)
    except (OSError, ValueError, RuntimeError, KeyError, LinkError) as e:
        print(f"boomfmi {args.command}: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:            # Ctrl-C, SIGINT: every command says so, no traceback, 128 + 2
        print(f"\nboomfmi {args.command}: interrupted", file=sys.stderr, flush=True)
        return 130


__all__ = ["COMMANDS", "build_parser", "main"]


if __name__ == "__main__":
    sys.exit(main())
