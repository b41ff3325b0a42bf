"""One FMI 2.0 co-simulation instance through fmpy, addressed by variable name.

``FmuInstance`` wraps ``fmpy.fmi2.FMU2Slave``: it extracts the FMU, collects the
FMU's log messages, sets and gets variables by name (or, on a master's hot path, through
:meth:`FmuInstance.real_writer` / :meth:`FmuInstance.real_reader`, which build their
value-reference arrays once), and turns a failed call into :class:`FmuError` carrying
the FMI status and the FMU's own message.
"""
from __future__ import annotations

import itertools
import shutil
import weakref
import zipfile
from ctypes import byref
from pathlib import Path
from typing import Iterable, Mapping

from fmpy import calloc, extract, free, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, fmi2Real, fmi2ValueReference)

from ..names import name_problem

try:
    from fmpy.logging import addLoggerProxy
except (ImportError, OSError):  # pragma: no cover - fmpy without its native logging proxy
    addLoggerProxy = None

STATUS = ("ok", "warning", "discard", "error", "fatal", "pending")
#: the worst status a hot-path call may return without raising (fmi2Warning)
_WARNING = 1

# fmpy's native logger proxy (which formats the FMU's printf-style messages) keeps ONE
# Python logger for the whole process: the last one registered.  So every instance
# registers the same dispatcher, and tells its messages apart by the component
# environment it hands the FMU at instantiation, which the FMU passes back with each.
_INSTANCES: dict[int, "weakref.ref[FmuInstance]"] = {}
_ENVIRONMENTS = itertools.count(1)


def _dispatch(env, instance_name, status, category, message):
    ref = _INSTANCES.get(env or 0)
    instance = ref() if ref is not None else None
    if instance is not None:
        instance._log(env, instance_name, status, category, message)


_LOGGER = fmi2CallbackLoggerTYPE(_dispatch)


class FmuError(RuntimeError):
    """An FMI call failed.  ``status`` is the FMI status (3 = fmi2Error, 4 = fmi2Fatal);
    the message names the instance, the call and what the FMU logged."""

    def __init__(self, instance: str, function: str, status: int, log: list[str]):
        self.instance, self.function, self.status, self.log = instance, function, status, log
        label = STATUS[status] if 0 <= status < len(STATUS) else "illegal status"
        detail = "; ".join(log) if log else "the FMU logged no message"
        super().__init__(f"{instance}: {function} returned fmi2{label.capitalize()}: {detail}")


def model_description(path):
    """fmpy's model description of the FMU at ``path``; a file that is not an FMU (not a
    zip archive, no or a broken modelDescription.xml) raises ``ValueError`` naming it."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such FMU")
    try:
        md = read_model_description(str(path))
    except zipfile.BadZipFile:
        raise ValueError(f"{path}: not an FMU (not a zip archive; a truncated or corrupted file?)") from None
    except KeyError as e:
        raise ValueError(f"{path}: not an FMU (no {e.args[0] if e.args else 'modelDescription.xml'} in it)") from None
    except Exception as e:           # fmpy's own parse and validation errors
        raise ValueError(f"{path}: not a valid FMU: {e}") from None
    for kind in ("coSimulation", "modelExchange"):   # fmpy loads binaries/<platform>/<identifier>.so
        identifier = getattr(getattr(md, kind, None), "modelIdentifier", None)
        problem = None if identifier is None else name_problem(identifier)
        if problem:
            raise ValueError(f"{path}: not a valid FMU: its {kind} modelIdentifier {identifier!r} is refused "
                             f"(it names the FMU's library): {problem}")
    return md


class FmuInstance:
    """An instantiated co-simulation FMU.

    Parameters
    ----------
    path : path of the ``.fmu`` file.
    name : instance name (defaults to the model name).
    debug_logging : ask the FMU for debug messages too.
    """

    def __init__(self, path, name: str | None = None, debug_logging: bool = False):
        self.path = Path(path)
        self.model_description = model_description(self.path)
        self.name = name or self.model_description.modelName
        self.variables = {v.name: v for v in self.model_description.modelVariables}
        self.messages: list[tuple[int, str]] = []
        self._unzip_dir = extract(str(self.path))
        self._env = next(_ENVIRONMENTS)
        _INSTANCES[self._env] = weakref.ref(self)
        self._callbacks = fmi2CallbackFunctions()
        self._callbacks.logger = _LOGGER
        self._callbacks.componentEnvironment = self._env
        self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        if addLoggerProxy is not None:
            addLoggerProxy(byref(self._callbacks))
        try:
            self.fmu = FMU2Slave(guid=self.model_description.guid, unzipDirectory=self._unzip_dir,
                                 modelIdentifier=self.model_description.coSimulation.modelIdentifier,
                                 instanceName=self.name)
            self._call("fmi2Instantiate", self.fmu.instantiate, callbacks=self._callbacks,
                       loggingOn=debug_logging)
            self._do_step = self._raw("fmi2DoStep")
        except BaseException:
            _INSTANCES.pop(self._env, None)
            shutil.rmtree(self._unzip_dir, ignore_errors=True)
            raise
        self._closed = False
        self.time = 0.0
        self._sets = 0      # counts the calls that set variables (a writer's skip checks it)

    # -- logging and errors ------------------------------------------------------------
    def _log(self, env, instance_name, status, category, message):
        text = message.decode("utf-8", "replace") if isinstance(message, bytes) else str(message)
        self.messages.append((int(status), text))

    def _call(self, function: str, fn, *args, **kwargs):
        first = len(self.messages)
        try:
            return fn(*args, **kwargs)
        except FMICallException as e:
            status = int(getattr(e, "status", 3))
            raise FmuError(self.name, function, status,
                           [m for s, m in self.messages[first:] if s >= 1]) from None
        except Exception as e:
            if function == "fmi2Instantiate":
                raise FmuError(self.name, function, 3,
                               [m for _, m in self.messages[first:]] or [str(e)]) from None
            raise

    # -- variables -------------------------------------------------------------------------
    def value_references(self, names: Iterable[str]) -> list[int]:
        """Value references of ``names``; raises KeyError naming an unknown variable."""
        refs = []
        for n in names:
            if n not in self.variables:
                raise KeyError(f"{self.name}: no variable {n!r} in {self.path.name}")
            refs.append(self.variables[n].valueReference)
        return refs

    def set(self, values: Mapping[str, object] | None = None, **kw) -> None:
        """Set variables by name; each value is converted to the variable's type."""
        self._sets += 1
        values = dict(values or {}, **kw)
        groups: dict[str, tuple[list, list]] = {}
        for n, value in values.items():
            self.value_references([n])
            var = self.variables[n]
            vrs, vals = groups.setdefault(var.type, ([], []))
            vrs.append(var.valueReference)
            vals.append(value)
        for typ, (vrs, vals) in groups.items():
            if typ == "Real":
                self._call("fmi2SetReal", self.fmu.setReal, vrs, [float(v) for v in vals])
            elif typ in ("Integer", "Enumeration"):
                self._call("fmi2SetInteger", self.fmu.setInteger, vrs, [int(v) for v in vals])
            elif typ == "Boolean":
                self._call("fmi2SetBoolean", self.fmu.setBoolean, vrs, [bool(v) for v in vals])
            else:
                self._call("fmi2SetString", self.fmu.setString, vrs, [str(v) for v in vals])

    def get(self, *names: str) -> dict[str, object]:
        """Values of the named variables (all outputs when none is named)."""
        if not names:
            names = tuple(u.variable.name for u in self.model_description.outputs)
        out = {}
        for n in names:
            self.value_references([n])
            var = self.variables[n]
            vr = [var.valueReference]
            if var.type == "Real":
                out[n] = self._call("fmi2GetReal", self.fmu.getReal, vr)[0]
            elif var.type in ("Integer", "Enumeration"):
                out[n] = self._call("fmi2GetInteger", self.fmu.getInteger, vr)[0]
            elif var.type == "Boolean":
                out[n] = self._call("fmi2GetBoolean", self.fmu.getBoolean, vr)[0]
            else:
                out[n] = self._call("fmi2GetString", self.fmu.getString, vr)[0]
        return out

    def set_real(self, vrs: list[int], values: list[float]) -> None:
        """Set Real variables by value reference."""
        self._sets += 1
        self._call("fmi2SetReal", self.fmu.setReal, vrs, values)

    def get_real(self, vrs: list[int]) -> list[float]:
        """Real variables by value reference."""
        return self._call("fmi2GetReal", self.fmu.getReal, vrs)

    # -- a master's hot path ---------------------------------------------------------------
    # fmpy's setReal/getReal build both ctypes arrays on every call and pass through its
    # call logger; a master that sets and gets the same variables every step builds them
    # once and calls the FMU's function directly.  Errors are raised as by _call.
    def _raw(self, function: str):
        return self.fmu._functions[function], self.fmu.component

    def _failed(self, function: str, status: int, first: int) -> FmuError:
        return FmuError(self.name, function, status, [m for s, m in self.messages[first:] if s >= 1])

    def real_writer(self, vrs: list[int]):
        """``write(values)``: fmi2SetReal of the Real variables ``vrs`` (value
        references), with one value per reference, in their order.  Inputs keep
        their values until set again (FMI 2.0, 4.2.1), so a write of the values this
        writer wrote last is skipped, unless anything else was set on the instance since."""
        n = len(vrs)
        refs, buf = (fmi2ValueReference * n)(*vrs), (fmi2Real * n)()
        fn, c = self._raw("fmi2SetReal")
        messages = self.messages
        last: list = [None, 0]          # the values written last, and self._sets after writing them

        def write(values: list) -> None:
            if values == last[0] and last[1] == self._sets:
                return
            buf[:] = values
            first = len(messages)
            status = fn(c, refs, n, buf)
            if status > _WARNING:
                last[0] = None
                raise self._failed("fmi2SetReal", status, first)
            self._sets += 1
            last[0], last[1] = list(values), self._sets
        return write

    def real_reader(self, vrs: list[int]):
        """``read()``: fmi2GetReal of the Real variables ``vrs`` (value references);
        returns a ctypes array of their values in that order, overwritten by the next
        ``read()``."""
        n = len(vrs)
        refs, buf = (fmi2ValueReference * n)(*vrs), (fmi2Real * n)()
        fn, c = self._raw("fmi2GetReal")
        messages = self.messages

        def read():
            first = len(messages)
            status = fn(c, refs, n, buf)
            if status > _WARNING:
                raise self._failed("fmi2GetReal", status, first)
            return buf
        return read

    # -- life cycle ------------------------------------------------------------------------
    def initialize(self, parameters: Mapping[str, object] | None = None, start_time: float = 0.0,
                   stop_time: float | None = None, inputs: Mapping[str, object] | None = None) -> None:
        """Set up the experiment, apply parameters and inputs, and leave initialisation."""
        self._call("fmi2SetupExperiment", self.fmu.setupExperiment, startTime=start_time,
                   stopTime=stop_time)
        if parameters:
            self.set(parameters)
        self._call("fmi2EnterInitializationMode", self.fmu.enterInitializationMode)
        if inputs:
            self.set(inputs)
        self._call("fmi2ExitInitializationMode", self.fmu.exitInitializationMode)
        self.time = start_time

    def step(self, dt: float) -> None:
        """One communication step of ``dt`` [s] from the current time."""
        self._call("fmi2DoStep", self.fmu.doStep, currentCommunicationPoint=self.time,
                   communicationStepSize=dt)
        self.time += dt

    def step_to(self, t: float, dt: float) -> None:
        """One communication step of ``dt`` [s] from ``t`` (hot path)."""
        fn, c = self._do_step
        first = len(self.messages)
        status = fn(c, t, dt, 1)
        if status > _WARNING:
            raise self._failed("fmi2DoStep", status, first)
        self.time = t + dt

    def close(self) -> None:
        """Terminate (when possible), free the instance and remove the extracted files."""
        if self._closed:
            return
        self._closed = True
        try:
            self.fmu.terminate()
        except Exception:
            pass
        try:
            self.fmu.freeInstance()
        finally:
            _INSTANCES.pop(self._env, None)
            shutil.rmtree(self._unzip_dir, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def run_table(path, table, parameters: Mapping[str, object] | None = None,
              outputs: Iterable[str] | None = None):
    """Drive an FMU through a table of inputs; return the outputs at each row's time.

    ``table`` is a pandas DataFrame with a ``time`` column [s] and one column per
    input.  At row i the inputs are set, the outputs are read (they belong to time
    t_i), and the FMU steps to t_(i+1).  This is the replay of the Reference-FMUs'
    ``<model>_in.csv`` / ``<model>_ref.csv`` pairs.
    """
    import pandas as pd

    times = table["time"].to_numpy(dtype=float)
    inputs = [c for c in table.columns if c != "time"]
    with FmuInstance(path) as fmu:
        outputs = list(outputs) if outputs is not None else [
            u.variable.name for u in fmu.model_description.outputs]
        fmu.initialize(parameters, start_time=float(times[0]), stop_time=float(times[-1]),
                       inputs={c: table[c].iloc[0] for c in inputs})
        rows = []
        for i, t in enumerate(times):
            fmu.set({c: table[c].iloc[i] for c in inputs})
            rows.append({"time": t, **fmu.get(*outputs)})
            if i + 1 < len(times):
                fmu.step(float(times[i + 1] - t))
    return pd.DataFrame(rows)


__all__ = ["STATUS", "FmuError", "model_description", "FmuInstance", "run_table"]
