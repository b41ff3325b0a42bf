"""A machine is a set of joints (issue 32, item 1): the boom rig is the one-joint
``Machine``, the excavator the four-joint one; one reference module with one entry
``simulate(machine, ...)`` choosing the boom's event-driven solve or the linkage's fixed
step; one naming rule for channels and parameters."""
import importlib

import numpy as np
import pandas as pd
import pytest

from boomfmi import experiments as E
from boomfmi.model import Model, fmu_variable
from boomfmi.model import machine as M
from boomfmi.model import reference as R
from boomfmi.physics import ParameterError
from boomfmi.physics.linkage import JOINTS
from boomfmi.physics.params import channel

LEAK = {"piston_leakage": {"C": 2e-11}}
#: Where the boom's identified parameters live in its SSP (``excavator_boom.ssp``, as params.ssv binds them)
SSP_NAMES = {"K_v": "boom_load.K_v", "F_s": "boom_load.F_s", "F_d": "boom_load.F_d",
             "F_L": "boom_load.F_L", "M": "boom_load.M", "A_max": "valve.A_max"}


def test_one_machine_class_and_one_reference_module():
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("boomfmi.model.excavator_reference")
    with pytest.raises(ModuleNotFoundError):                 # the linkage is physics/linkage.py
        importlib.import_module("boomfmi.physics.excavator")
    for gone in ("boomfmi.identify.excavator", "boomfmi.identify.excavator_outputs"):   # folded into identify/
        with pytest.raises(ModuleNotFoundError):
            importlib.import_module(gone)
    assert M.ExcavatorMachine is M.Machine
    assert R.simulate_excavator_reference is R.simulate_linkage
    assert type(M.excavator_machine()) is type(M.boom_machine(Model())) is M.Machine


def test_naming_rule_one_joint_bare_more_joints_suffixed():
    assert channel("angle", "boom", 1) == "alpha" and channel("p_a", "boom", 1) == "p_a"
    assert channel("angle", "arm", 4) == "angle_arm" and channel("K_v", "arm", 4) == "K_v_arm"
    boom, ex = M.boom_machine(Model()), M.excavator_machine()
    assert (boom.names, boom.n, boom.mechanism) == (("boom",), 1, "boom")
    assert (ex.names, ex.n, ex.mechanism) == (JOINTS, 4, "linkage")
    assert boom.channel("angle", "boom") == "alpha" and ex.channel("angle", "boom") == "angle_boom"
    assert boom.param_name("K_v", "boom") == "K_v" and ex.param_name("K_v", "arm") == "K_v_arm"
    # the boom's SSP names are identification's, the excavator's the linkage's options
    assert {p: boom.ssp_name(p) for p in SSP_NAMES} == SSP_NAMES     # the names identify's params.ssv binds
    assert ex.ssp_name("F_s_arm") == "linkage.F_s_arm" and ex.ssp_name("A_max_arm") == "valve_arm.A_max"
    assert boom.fmu_variable("valve_dynamics", "tau", "boom") == fmu_variable("valve_dynamics", "tau")
    assert ex.fmu_variable("valve_dynamics", "tau", "arm") == "valve_arm.tau_spool"
    assert boom.fmu_variable("stribeck_friction", "v_s", "boom") == "boom_load.v_s"
    assert ex.fmu_variable("stribeck_friction", "v_s", "arm") == "linkage.v_s_arm"
    assert boom.fmu_variable("sensor_lag", "tau", "boom") is None


def test_boom_machine_is_the_boom_rig_and_refuses_other_joints():
    model = Model(x0=0.02, p_a0=3e5, p_b0=2e5, effects=LEAK)
    m = M.boom_machine(model)
    (joint,) = m.joints
    assert joint.name == "boom" and joint.model == model
    x0, p_a0, p_b0 = m.start()
    assert (x0.tolist(), p_a0.tolist(), p_b0.tolist()) == ([0.02], [3e5], [2e5])
    assert m.booms()[0].model.effects == LEAK and m.cylinders == (model.cylinder,)
    with pytest.raises(ParameterError, match="joint = 'arm'.*boom"):
        m.fmu_variable("valve_dynamics", "tau", "arm")
    with pytest.raises(ParameterError, match=r"effects = 'arm'.*not a joint of the boom \(boom\)"):
        M.Machine(ex=None, model=Model(), effects={"arm": LEAK}).check()
    with pytest.raises(ParameterError, match=r"effects\.boom\.piston_leakage"):
        M.boom_machine(Model(effects={"piston_leakage": {"C": -1.0}})).check()


def test_simulate_dispatches_by_mechanism():
    model = Model(effects=LEAK)
    cmd = E.random_steps(seed=1, duration=0.3)
    boom = R.simulate(M.boom_machine(model), cmd, 0.3, breakpoints=cmd.breakpoints)
    pd.testing.assert_frame_equal(boom, R.simulate_reference(model, cmd, 0.3, breakpoints=cmd.breakpoints))
    assert "alpha" in boom and np.ptp(boom["p_b"]) > 1e5
    machine = M.excavator_machine(effects={"arm": LEAK})
    dig = E.digging_cycle()
    ex = R.simulate(machine, dig, 0.02, h=1e-4)
    pd.testing.assert_frame_equal(ex, R.simulate_linkage(dig, 0.02, machine, h=1e-4))
    assert "angle_arm" in ex and len(ex) == 21
    with pytest.raises(ValueError, match="not the boom's load: use simulate"):
        R.simulate_linkage(dig, 0.02, M.boom_machine(model))
