"""Mechanical systems with unilateral constraints (Eq. (1)) and the biped instance."""

from biped_opt.model.biped import Biped
from biped_opt.model.modes import ContactMode
from biped_opt.model.params import BipedParams
from biped_opt.systems.mechanics import (
    MechanicalSystem,
    accelerations,
    impact_map,
    reaction_forces,
)

__all__ = [
    "Biped",
    "BipedParams",
    "ContactMode",
    "MechanicalSystem",
    "accelerations",
    "impact_map",
    "reaction_forces",
]
