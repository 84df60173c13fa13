"""Geometry of the rigorous pushbroom model: frames, rotations, interior and exterior
orientation, collinearity, terrain.  Conventions: ``docs/conventions.md``."""
