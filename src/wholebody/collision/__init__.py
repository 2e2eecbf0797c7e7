"""Collision avoidance: the robot's and the environment's collision shapes, the pairs checked,
their distances and distance Jacobians (:mod:`.model`); the constraint that keeps them apart is
:class:`wholebody.tasks.CollisionAvoidance`."""

from __future__ import annotations

from wholebody.collision.model import SHAPES, CollisionModel, Obstacle, PairDistance

__all__ = ["SHAPES", "CollisionModel", "Obstacle", "PairDistance"]
