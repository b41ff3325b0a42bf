"""The assembled boom model, once: its parameter set with any effects switched on
(:class:`Model`), prepared for stepping (:class:`Boom`), and the catalogue of effects
(:data:`EFFECTS`).  The FMUs, the monolithic reference (:mod:`.reference`, imported on
its own: it needs scipy and pandas, which the FMUs do not carry), the virtual rig and
diagnosis all step this model.  Only relative imports are used inside this package, so
that ``build_fmus.py`` can bundle it into each FMU beside the physics.
"""
from .boom import Boom, Model, check_effects, lagged, measure
from .catalogue import EFFECTS, PENDING, STAGES, Effect, Parameter, effects_from_options, fmu_variable, of_fmu

__all__ = ["Boom", "Model", "check_effects", "lagged", "measure", "EFFECTS", "PENDING", "STAGES", "Effect",
           "Parameter", "effects_from_options", "fmu_variable", "of_fmu"]
