"""One machine rig and one bridge, for one joint or four (issue 32, plan 2.4 and 2.7).

The boom's VirtualRig and the excavator's ExcavatorRig are the same MachineRig (its
joints' JointPlant and a mechanism); the fold kept every sample byte-identical, pinned
here by a digest of a short noisy run with effects.  The two bridge FMUs' variables come
from rigbridge.bridge_variables and are the ones docs/interfaces.md documents."""
import hashlib
import importlib.util
import math
import re
from pathlib import Path

import pytest

from boomfmi.rig import ExcavatorRig, JointPlant, MachineRig, VirtualRig, load_config
from boomfmi.rigbridge import bridge_variables, channels

ROOT = Path(__file__).resolve().parents[1]
NOISE = {"p_sigma": 500.0, "alpha_sigma": 2e-4, "quantise": True}


def _u(t, k=0):
    return 5.0 + 3.0 * math.sin(2 * math.pi * (0.7 + 0.3 * k) * t + k)


def _digest(rig, command, n=150):
    h = hashlib.sha256(repr(tuple(rig.measure())).encode())
    for k in range(n):
        h.update(repr(tuple(rig.step(command(k * 1e-3), 1e-3 if k % 7 else 1.3e-3))).encode())
    return h.hexdigest()[:16]


def test_the_boom_and_the_excavator_are_one_machine_rig_of_joint_plants():
    boom = VirtualRig()
    ex = ExcavatorRig({"machine": "excavator"})
    assert isinstance(boom, MachineRig) and isinstance(ex, MachineRig)
    assert [type(j) for j in boom.joints] == [JointPlant]
    assert [j.name for j in ex.joints] == ["swing", "boom", "arm", "bucket"]
    assert all(isinstance(j, JointPlant) for j in ex.joints)
    assert importlib.util.find_spec("boomfmi.rig.excavator") is None     # no second rig module


def test_the_fold_kept_the_boom_rigs_samples_bit_for_bit():
    rig = VirtualRig(load_config(ROOT / "examples/rig/all_effects.json"))
    assert _digest(rig, _u) == "4a0cab5e4439481f"
    rig.reset()                                   # the noise restarts from the seed
    assert _digest(rig, _u) == "4a0cab5e4439481f"


def test_the_fold_kept_the_excavator_rigs_samples_bit_for_bit():
    rig = ExcavatorRig({"machine": "excavator", "seed": 11, "payload": 0.5, "noise": NOISE,
                        "contact": {"type": "ground", "ground_z": 0.0, "stiffness": 1500.0, "damping": 100.0},
                        "joints": {"arm": {"effects": {"piston_leakage": {"A_leak": 3e-8}, "sensor_lag": True,
                                                       "heat_transfer": True}},
                                   "bucket": {"effects": {"stribeck_friction": True, "pressure_friction": True,
                                                          "valve_dynamics": True, "end_cushioning": True}}}})
    assert _digest(rig, lambda t: [_u(t, k) for k in range(4)]) == "771a5c63a083dd39"


def _documented(fmu: str):
    """(name, causality, unit, start, bounds, description) of each row of the FMU's table
    in docs/interfaces.md."""
    text = (ROOT / "docs/interfaces.md").read_text()
    section = text.split(f"### `{fmu}`:", 1)[1].split("\n### ", 1)[0]
    rows = [r for r in section.splitlines() if r.startswith("| `")]
    return [tuple(c.strip() for c in r.strip("|").split(" | ")) for r in rows]


@pytest.mark.parametrize("machine, fmu", [("boom", "hardware_bridge"), ("excavator", "excavator_bridge")])
def test_each_bridges_variables_are_its_documented_interface(machine, fmu):
    declared = bridge_variables(machine)
    order = {"input": 0, "output": 1, "parameter": 2}
    documented = _documented(fmu)
    assert [(f"`{v.name}`", v.causality) for v in sorted(declared, key=lambda v: order[v.causality])] == \
        [d[:2] for d in documented]
    for v, d in zip(sorted(declared, key=lambda v: order[v.causality]), documented):
        assert d[5].startswith(v.description), v.name
    names = {v.name for v in declared}
    measured, extra, commands = channels(machine)
    assert set(measured) | set(extra) | set(commands) <= names
    assert {"u_applied" + c[1:] for c in commands} <= names
    assert re.fullmatch(r"(p_a|p_b|alpha)|(p_a|p_b|angle)_(swing|boom|arm|bucket)", measured[-1])
