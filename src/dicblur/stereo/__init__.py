"""Stereo DIC under motion blur (issue 29, docs/stereo.md): a calibrated rig, a synthetic
stereo laboratory, stereo correlation and triangulation, and the 3-D uncertainty of every
point (noise and each camera's own blur) propagated through the triangulation."""

from __future__ import annotations

from .camera import CameraModel, StereoRig, load_rig, rotation_matrix, save_rig
from .core import track
from .triangulate import propagate, triangulate, triangulation_jacobian

__all__ = [
    "CameraModel",
    "StereoRig",
    "load_rig",
    "propagate",
    "rotation_matrix",
    "save_rig",
    "track",
    "triangulate",
    "triangulation_jacobian",
]
