"""The rig link: authenticated fixed-size UDP datagrams between the hardware bridge and
the rig (``protocol``), and the bridge's side of the exchange (``client``).

This package uses the standard library only and relative imports, so that
``build_fmus.py`` can bundle it into the hardware-bridge FMU.
"""

#: the package exports no names of its own: its modules are imported by name
__all__ = []
