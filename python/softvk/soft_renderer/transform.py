"""Cameras: world to screen coordinates (SPEC §1)."""

import math

import numpy as np
import torch
import torch.nn as nn

from . import functional as srf

__all__ = ["Projection", "LookAt", "Look", "Transform"]


def _default_eye(viewing_angle):
    """On -z, at the distance where the unit sphere just fills the view: 1 / tan(a) + 1; one
    eye per mesh ([batch, 3], no gradient) for a [batch] tensor of angles."""
    if torch.is_tensor(viewing_angle) and viewing_angle.numel() > 1:
        distance = 1.0 / torch.tan(viewing_angle.detach().reshape(-1) * (math.pi / 180)) + 1
        zero = torch.zeros_like(distance)
        return torch.stack((zero, zero, -distance), dim=1)
    return [0, 0, -(1.0 / math.tan(math.radians(float(viewing_angle))) + 1)]


class Projection(nn.Module):
    """A [batch, 3, 4] camera matrix with Brown distortion (``functional.projection``)."""

    def __init__(self, P, dist_coeffs=None, orig_size=512):
        """
        Args:
            P: [batch, 3, 4] projection matrices (tensor or numpy array).
            dist_coeffs: [batch, 5] ``(k1, k2, p1, p2, k3)``; ``None`` for no distortion.
            orig_size: the size in pixels of the image P maps to.
        """
        super(Projection, self).__init__()
        if isinstance(P, np.ndarray):
            P = torch.from_numpy(P)
        if P is None or P.ndimension() != 3 or P.shape[1] != 3 or P.shape[2] != 4:
            raise ValueError(
                "You need to provide a valid (batch_size)x3x4 projection matrix P "
                "(or use camera_mode='look_at' or 'look')"
            )
        if dist_coeffs is None:
            dist_coeffs = torch.zeros(P.shape[0], 5, dtype=torch.float32, device=P.device)
        elif isinstance(dist_coeffs, np.ndarray):
            dist_coeffs = torch.from_numpy(dist_coeffs)
        self.P = P
        self.dist_coeffs = dist_coeffs
        self.orig_size = orig_size

    def forward(self, vertices):
        """[batch, V, 3] world coordinates to screen coordinates."""
        return srf.projection(vertices, self.P, self.dist_coeffs, self.orig_size)


class LookAt(nn.Module):
    """A camera at an eye looking at the origin (``functional.look_at``), then perspective or
    orthographic projection."""

    def __init__(self, perspective=True, viewing_angle=30, viewing_scale=1.0, eye=None):
        """
        Args:
            perspective: perspective (``True``) or orthographic projection.
            viewing_angle: half the field of view in degrees (perspective): a number, or a
                tensor (one angle, or [batch], one per mesh; it may require a gradient).
            viewing_scale: scale of the orthographic projection.
            eye: [3] or [batch, 3]; ``None``: ``(0, 0, -(1 / tan(viewing_angle) + 1))``.
        """
        super(LookAt, self).__init__()
        self.perspective = perspective
        self.viewing_angle = viewing_angle
        self.viewing_scale = viewing_scale
        self._eye = eye if eye is not None else _default_eye(viewing_angle)

    def forward(self, vertices):
        vertices = srf.look_at(vertices, self._eye)
        if self.perspective:
            return srf.perspective(vertices, angle=self.viewing_angle)
        return srf.orthogonal(vertices, scale=self.viewing_scale)


class Look(nn.Module):
    """A camera at an eye looking along a direction (``functional.look``), then perspective or
    orthographic projection."""

    def __init__(self, camera_direction=[0, 0, 1], perspective=True, viewing_angle=30,
                 viewing_scale=1.0, eye=None):
        """
        Args:
            camera_direction: [3] or [batch, 3], the direction the camera looks along.
            perspective, viewing_angle, viewing_scale, eye: as :class:`LookAt`.
        """
        super(Look, self).__init__()
        self.perspective = perspective
        self.viewing_angle = viewing_angle
        self.viewing_scale = viewing_scale
        self.camera_direction = camera_direction
        self._eye = eye if eye is not None else _default_eye(viewing_angle)

    def forward(self, vertices):
        vertices = srf.look(vertices, self._eye, self.camera_direction)
        if self.perspective:
            return srf.perspective(vertices, angle=self.viewing_angle)
        return srf.orthogonal(vertices, scale=self.viewing_scale)


class Transform(nn.Module):
    """The renderer's camera: ``camera_mode`` ``'projection'``, ``'look'`` or ``'look_at'``."""

    def __init__(self, camera_mode="projection", P=None, dist_coeffs=None, orig_size=512,
                 perspective=True, viewing_angle=30, viewing_scale=1.0,
                 eye=None, camera_direction=[0, 0, 1]):
        """
        Args:
            camera_mode: ``'projection'`` (needs ``P``), ``'look'`` or ``'look_at'``.
            P, dist_coeffs, orig_size: as :class:`Projection`.
            perspective, viewing_angle, viewing_scale, eye: as :class:`LookAt`.
            camera_direction: as :class:`Look`.
        """
        super(Transform, self).__init__()
        self.camera_mode = camera_mode
        if camera_mode == "projection":
            self.transformer = Projection(P, dist_coeffs, orig_size)
        elif camera_mode == "look":
            self.transformer = Look(camera_direction=camera_direction, perspective=perspective,
                                    viewing_angle=viewing_angle, viewing_scale=viewing_scale,
                                    eye=eye)
        elif camera_mode == "look_at":
            self.transformer = LookAt(perspective, viewing_angle, viewing_scale, eye)
        else:
            raise ValueError("Camera mode has to be one of projection, look or look_at")

    def forward(self, mesh):
        """Replaces ``mesh.vertices`` by their screen coordinates; returns ``mesh``."""
        mesh.vertices = self.transformer(mesh.vertices)
        return mesh

    def set_eyes_from_angles(self, distances, elevations, azimuths):
        """Sets the eye(s) from distance, elevation and azimuth in degrees (numbers, or tensors
        for one eye per mesh of the batch); see ``functional.get_points_from_angles``."""
        if self.camera_mode not in ("look", "look_at"):
            raise ValueError("Projection does not need to set eyes")
        self.transformer._eye = srf.get_points_from_angles(distances, elevations, azimuths)

    def set_eyes(self, eyes):
        """Sets the eye(s): [3] or [batch, 3]."""
        if self.camera_mode not in ("look", "look_at"):
            raise ValueError("Projection does not need to set eyes")
        self.transformer._eye = eyes

    @property
    def eyes(self):
        """The eye(s) as last set (SoftRas's property read a misspelt attribute and failed)."""
        if self.camera_mode not in ("look", "look_at"):
            raise AttributeError("a projection camera has no eyes")
        return self.transformer._eye
