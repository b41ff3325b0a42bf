"""The reference rig: every constant of ``shared/spec/reference-rig.md``, in SI units.

These are the default parameter values of every FMU, of the monolithic reference
solver and of the virtual rig.  A value is the paper's unless the spec marks it as
chosen; the paper's errata (P_cr, T, A_b, Eq. 1, the valve's sign, Eq. 17) are
corrected here and documented in ``docs/paper-errata.md``.
"""
from __future__ import annotations

import math

#: Ratio of specific heats of air, k [1].
k = 1.4
#: Specific gas constant of air, R [J/(kg K)].
R = 287.0
#: Air temperature, T [K] (20 degC; the paper's "273 K" is an erratum).
T = 293.15
#: Atmospheric pressure, P_atm [Pa].
P_atm = 101_325.0

#: Cylinder bore (DSNU 32-60) [m].
bore = 0.032
#: Piston-rod diameter [m].
rod = 0.012
#: Cap-side piston area A_a = pi/4 bore^2 [m^2].
A_a = math.pi / 4.0 * bore**2
#: Rod-side annulus area A_b = pi/4 (bore^2 - rod^2) [m^2] (the paper prints the rod's own section).
A_b = math.pi / 4.0 * (bore**2 - rod**2)
#: Stroke L [m].
L = 0.060
#: Dead volume of chamber A incl. port and hose, V_a0 [m^3].
V_a0 = 1.5e-5
#: Dead volume of chamber B incl. port and hose, V_b0 [m^3].
V_b0 = 1.5e-5

#: Maximum orifice area of each valve port, A_max [m^2].
A_max = 4.0e-6
#: Supply pressure, absolute, P_s [Pa] (0.6 MPa gauge).
P_s = P_atm + 600_000.0
#: Exhaust pressure, absolute, P_e [Pa].
P_e = P_atm
#: Valve command that closes every port, u_centre [V].
u_centre = 5.0
#: Command range [V].
u_min, u_max = 0.0, 10.0

#: Boom geometry of Eq. 10 to 12 [m].
a = 0.15
b = 0.30
h = 0.05
l_min = 0.20

#: Load and friction, the paper's identified values (Eq. 8, 9, 13 to 17).
K_v = 2829.0      #: viscous friction coefficient [N s/m]
F_s = 113.255     #: static friction force [N]
F_d = 85.727      #: Coulomb friction force [N]
F_L = 261.177     #: load force from the backhoe's weight [N]
M = 22.7          #: moving mass reduced to the piston [kg]


__all__ = ["k", "R", "T", "P_atm", "bore", "rod", "A_a", "A_b", "L", "V_a0", "V_b0", "A_max", "P_s", "P_e", "u_centre",
           "u_min", "u_max", "a", "b", "h", "l_min", "K_v", "F_s", "F_d", "F_L", "M"]
