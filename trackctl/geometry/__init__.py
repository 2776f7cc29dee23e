"""Cameras, frames and rotations."""

from trackctl.geometry.camera import PinholeCamera, look_at

__all__ = ["PinholeCamera", "look_at"]
