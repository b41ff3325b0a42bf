"""Third-party import: libcosim (through libcosimpy) runs the packed .ssp, and agrees
with boomfmi's Jacobi master at the same step to 1e-6 relative."""
from __future__ import annotations

import numpy as np
import pytest

from boomfmi.system import simulate_ssp

libcosimpy = pytest.importorskip("libcosimpy", reason="libcosimpy is a test dependency")

STEP_NS = 1_000_000          # 1 ms
N_STEPS = 1500


def command(t: float) -> float:
    return 10.0 if t < 0.5 else 1.0


def run_libcosim(ssp_path):
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.WARNING)
    from boomfmi.fmubuild.ssp import osp_ssp     # libcosim refuses system connectors
    ex = CosimExecution.from_ssp_file(str(osp_ssp(ssp_path)), step_size=STEP_NS)
    idx = {n: ex.slave_index_from_instance_name(n) for n in ("valve", "cylinder", "boom_load")}
    ref = {(n, v.name.decode()): v.reference for n, i in idx.items() for v in ex.slave_variables(i)}
    observer = CosimObserver.create_last_value()
    manipulator = CosimManipulator.create_override()
    assert ex.add_observer(observer) and ex.add_manipulator(manipulator)
    rows = []
    u_now = None
    for k in range(N_STEPS):
        u = command(k * STEP_NS / 1e9)
        if u != u_now:      # takes effect in this very step, before fmi2DoStep(t_k)
            assert manipulator.slave_real_values(idx["valve"], [ref[("valve", "u")]], [u])
            u_now = u
        assert ex.step()
        x = observer.last_real_values(idx["boom_load"], [ref[("boom_load", "x")]])[0]
        p_a, p_b = observer.last_real_values(idx["cylinder"], [ref[("cylinder", "p_a")], ref[("cylinder", "p_b")]])
        rows.append((ex.status().current_time / 1e9, x, p_a, p_b))
    # the parameters of the per-component bindings were applied
    A_max = observer.last_real_values(idx["valve"], [ref[("valve", "A_max")]])[0]
    return np.array(rows), A_max


def test_libcosim_runs_the_ssp_and_agrees_with_the_jacobi_master(ssp_path):
    lib, A_max = run_libcosim(ssp_path)
    assert A_max == pytest.approx(4e-6)
    ours = simulate_ssp(ssp_path, stop_time=N_STEPS * 1e-3, step=1e-3, algorithm="jacobi",
                        inputs=lambda t: {"valve.u": command(t)})
    ours = ours.iloc[1:]                       # libcosim's k-th sample is our row at t_(k+1)
    np.testing.assert_allclose(lib[:, 0], ours["time"], rtol=0, atol=1e-12)
    for j, col in enumerate(("boom_load.x", "cylinder.p_a", "cylinder.p_b"), start=1):
        np.testing.assert_allclose(lib[:, j], ours[col], rtol=1e-6, atol=1e-12, err_msg=col)
    assert lib[-1, 1] == pytest.approx(0.06)                  # the boom extended fully
    assert lib[-1, 2] == pytest.approx(701325.0, rel=1e-3)    # chamber A at supply
