"""Torque-level whole-body control: accelerations, torques and contact wrenches from the same
task objects as the velocity backends (:class:`DynamicsSolver`), with patch and point
contacts (:mod:`wholebody.dynamics.contacts`)."""

from wholebody.dynamics.contacts import Contact, PatchContact, PointContact
from wholebody.dynamics.solver import DynamicsResult, DynamicsSolver

__all__ = ["Contact", "DynamicsResult", "DynamicsSolver", "PatchContact", "PointContact"]
