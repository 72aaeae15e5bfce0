"""Entities E of the knowledge base: the names of :mod:`llcps.sim.specs` (what a scene
holds), :mod:`llcps.sim.builders` (how a scene is written) and :mod:`llcps.sim.bodies`
(the PyBullet bodies), gathered for code that imports them from one place."""

from __future__ import annotations

from llcps.sim.bodies import Entity, build_entity, build_fixture
from llcps.sim.builders import DEFAULT_DENSITY, bucket, edge_lip, inside, open_box, shelf, solid, stacked
from llcps.sim.specs import DEFAULT_WALL, FIXTURE_RGBA, KINDS, RGBA, EntitySpec, FixtureSpec, TableSpec

__all__ = [
    "DEFAULT_DENSITY",
    "DEFAULT_WALL",
    "FIXTURE_RGBA",
    "KINDS",
    "RGBA",
    "Entity",
    "EntitySpec",
    "FixtureSpec",
    "TableSpec",
    "build_entity",
    "build_fixture",
    "bucket",
    "edge_lip",
    "inside",
    "open_box",
    "shelf",
    "solid",
    "stacked",
]
