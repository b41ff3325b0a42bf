"""The 5/3 proportional valve (MPYE-5-1/4-010B): opening A(u) and port routing.

Routing follows the reference rig (the paper's text states the opposite sign, which
its own experiment contradicts; see ``docs/paper-errata.md``):

* u < 5 V: supply -> A and B -> exhaust, the piston extends;
* u > 5 V: supply -> B and A -> exhaust, the piston retracts;
* u = 5 V: every port closed.
"""
from __future__ import annotations

from . import _xp as xp
from .orifice import signed_mass_flow, signed_mass_flow_and_slope, signed_mass_flow_slope
from .params import Gas, Valve


def orifice_area(u, valve: Valve = Valve()):
    """A(u) = A_max min(|u - u_centre| / u_span, 1) [m^2], the same for every open port."""
    return valve.A_max * xp.minimum(xp.abs_(u - valve.u_centre) / valve.u_span, 1.0)


def chamber_flows(u, p_a, p_b, valve: Valve = Valve(), gas: Gas = Gas()):
    """Mass flows into chambers A and B, ``(mdot_a, mdot_b)`` [kg/s].

    Parameters
    ----------
    u : float or array
        Valve command [V], 0 to 10.
    p_a, p_b : float or array
        Absolute chamber pressures [Pa].

    Each chamber's port sees the supply or the exhaust depending on the sign of
    u - u_centre; a flow is positive into its chamber, so an exhausting chamber has a
    negative flow.
    """
    A = orifice_area(u, valve)
    extend = u < valve.u_centre
    port_a = xp.where(extend, valve.P_s, valve.P_e)
    port_b = xp.where(extend, valve.P_e, valve.P_s)
    return signed_mass_flow(A, port_a, p_a, gas), signed_mass_flow(A, port_b, p_b, gas)


def chamber_flow_slopes(u, p_a, p_b, valve: Valve = Valve(), gas: Gas = Gas()):
    """``(d mdot_a / d p_a, d mdot_b / d p_b)`` [kg/(s Pa)]: how each chamber's inflow
    falls as its own pressure rises (both <= 0).

    A co-simulation passes these with the flows so that the cylinder can integrate its
    chambers against the valve's local linearisation instead of a held flow (the chamber
    time constant, a few milliseconds, is close to the communication step).
    """
    A = orifice_area(u, valve)
    extend = u < valve.u_centre
    port_a = xp.where(extend, valve.P_s, valve.P_e)
    port_b = xp.where(extend, valve.P_e, valve.P_s)
    return (signed_mass_flow_slope(A, port_a, p_a, gas),
            signed_mass_flow_slope(A, port_b, p_b, gas))


def chamber_flows_and_slopes(u, p_a, p_b, valve: Valve = Valve(), gas: Gas = Gas()):
    """:func:`chamber_flows` and :func:`chamber_flow_slopes` at once: ``(mdot_a, mdot_b,
    dmdot_a/dp_a, dmdot_b/dp_b)`` [kg/s, kg/(s Pa)], each port's flow and slope from
    one evaluation of its orifice (``orifice.signed_mass_flow_and_slope``)."""
    A = orifice_area(u, valve)
    extend = u < valve.u_centre
    port_a = xp.where(extend, valve.P_s, valve.P_e)
    port_b = xp.where(extend, valve.P_e, valve.P_s)
    m_a, s_a = signed_mass_flow_and_slope(A, port_a, p_a, gas)
    m_b, s_b = signed_mass_flow_and_slope(A, port_b, p_b, gas)
    return m_a, m_b, s_a, s_b


__all__ = ["orifice_area", "chamber_flows", "chamber_flow_slopes", "chamber_flows_and_slopes"]
