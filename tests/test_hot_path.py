"""A master's hot path (FmuInstance.real_writer / real_reader / step_to, and
BoomSlave's get_real / set_real inside the FMUs) against the by-name path, through the
built valve FMU."""
from __future__ import annotations

import pytest

from boomfmi.physics import reference_rig
from boomfmi.system import FmuInstance
from boomfmi.system.instance import FmuError

OUTPUTS = ("mdot_a", "mdot_b", "dmdot_a_dp_a", "dmdot_b_dp_b")


def test_the_hot_path_reads_what_the_by_name_path_reads(fmu):
    with FmuInstance(fmu("valve")) as valve:
        valve.initialize()
        write = valve.real_writer(valve.value_references(["u", "p_a", "p_b"]))
        read = valve.real_reader(valve.value_references(OUTPUTS))
        for u, p_a, p_b in ((2.0, 2.0e5, 3.0e5), (8.0, 4.0e5, 1.5e5), (5.0, 3.0e5, 3.0e5)):
            write([u, p_a, p_b])
            fast = list(read())
            slow = valve.get(*OUTPUTS)
            assert fast == [slow[n] for n in OUTPUTS]
            assert valve.get("u", "p_a", "p_b") == {"u": u, "p_a": p_a, "p_b": p_b}
        assert fast[0] == fast[1] == 0.0 and (u, p_a, p_b) == (5.0, 3.0e5, 3.0e5)   # 5 V closes every port
        # one variable alone, and the same variable twice in a group
        assert list(valve.real_reader(valve.value_references(["u"]))()) == [5.0]
        assert list(valve.real_reader(valve.value_references(["p_a", "p_a"]))()) == [3.0e5, 3.0e5]


def test_a_skipped_write_is_made_again_after_another_set(fmu):
    """The writer skips values it wrote last, but not once anything else set the input."""
    with FmuInstance(fmu("valve")) as valve:
        valve.initialize()
        write = valve.real_writer(valve.value_references(["u"]))
        write([3.0])
        valve.set(u=7.0)
        write([3.0])                                  # the same values as its last write
        assert valve.get("u")["u"] == 3.0
        valve.set_real(valve.value_references(["u"]), [6.0])
        write([3.0])
        assert valve.get("u")["u"] == 3.0
        values = [4.0]
        write(values)
        values[0] = 2.0                               # the caller's list changed in place
        write(values)
        assert valve.get("u")["u"] == 2.0


def test_a_failing_call_on_the_hot_path_raises_with_the_fmus_message(fmu):
    with FmuInstance(fmu("valve")) as valve:
        valve.initialize()
        write = valve.real_writer(valve.value_references(["u", "p_a", "p_b"]))
        read = valve.real_reader(valve.value_references(OUTPUTS))
        write([7.0, -1.0e5, reference_rig.P_atm])
        with pytest.raises(FmuError) as e:
            read()
        assert e.value.function == "fmi2GetReal" and e.value.status == 3
        assert "p_a = -100000" in str(e.value)
        with pytest.raises(FmuError) as e:           # the instance stays failed, and says why
            valve.step_to(0.0, 1e-3)
        assert e.value.function == "fmi2DoStep" and "cannot step" in str(e.value)
