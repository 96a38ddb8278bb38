"""Particle–particle and particle–wall contact (imports ``particles`` only).

Broadphase (:mod:`.broadphase`) -> narrowphase (:mod:`.narrowphase`) -> projected Gauss–Seidel
contact solver (:class:`~fbmflow.contact.contact_set.ContactSet`); short-range repulsion
(:class:`~fbmflow.contact.repulsion.Repulsion`) is the soft
alternative.
"""
from .broadphase import BROADPHASES, candidate_pairs, plane_candidates
from .contact_set import ContactReport, ContactSet
from .lubrication import Lubrication
from .narrowphase import Contacts, Planes
from .overlap import Overlap, deepest_overlap
from .repulsion import Repulsion

__all__ = ["BROADPHASES", "candidate_pairs", "plane_candidates", "ContactReport", "ContactSet",
           "Contacts", "Lubrication", "Overlap", "Planes", "Repulsion", "deepest_overlap"]
