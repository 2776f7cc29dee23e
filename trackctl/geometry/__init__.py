"""Cameras, frames, rotations and floor plans."""

from trackctl.geometry.camera import PinholeCamera, look_at
from trackctl.geometry.floorplan import FloorPlan, Wall, line_of_sight, three_rooms

__all__ = ["FloorPlan", "PinholeCamera", "Wall", "line_of_sight", "look_at", "three_rooms"]
