"""Orbit camera: yaw/pitch/distance around a target; z is up in the world.

Every mesh the previewer draws is normalised into the unit sphere about the
origin (viewer/scene/mesh.py), so framing needs only the view's aspect: ``frame``
puts the camera where that sphere's silhouette spans ``FRAME_FILL`` of the
view's shorter side. The default camera is that framing for a square view at
a three-quarter angle (turned ``DEFAULT_YAW`` from the front, looking down
``DEFAULT_PITCH``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: The fraction of the view's shorter side the framed object's silhouette spans.
FRAME_FILL = 0.8
#: The three-quarter view: degrees around z (-90 looks along +y) and above the horizon.
DEFAULT_YAW, DEFAULT_PITCH = -55.0, 22.0
DEFAULT_FOV = 35.0
#: The field-of-view control's range, vertical degrees.
FOV_RANGE = (10.0, 90.0)


def framing_distance(fov: float, aspect: float = 1.0, radius: float = 1.0, fill: float = FRAME_FILL) -> float:
    """The distance at which a sphere of ``radius`` spans ``fill`` of the shorter
    side of a view with vertical field of view ``fov`` (degrees) and ``aspect`` (w / h)."""
    tan_v = math.tan(math.radians(fov) / 2)
    tan_half = min(tan_v, tan_v * aspect)  # the tighter of the vertical and horizontal half-angles
    return radius / math.sin(math.atan(fill * tan_half))


@dataclass
class OrbitCamera:
    yaw: float = DEFAULT_YAW      # degrees around z; -90 looks along +y
    pitch: float = DEFAULT_PITCH  # degrees above the horizon
    distance: float = field(default_factory=lambda: framing_distance(DEFAULT_FOV))
    target: tuple[float, float, float] = (0.0, 0.0, 0.0)
    fov: float = DEFAULT_FOV      # vertical, degrees
    near: float = 0.05
    far: float = 100.0

    def eye(self) -> np.ndarray:
        y, p = math.radians(self.yaw), math.radians(self.pitch)
        d = np.array([math.cos(p) * math.cos(y), math.cos(p) * math.sin(y), math.sin(p)])
        return np.asarray(self.target, dtype=np.float64) + d * self.distance

    def view(self) -> np.ndarray:
        eye, tgt = self.eye(), np.asarray(self.target, dtype=np.float64)
        f = tgt - eye
        f /= np.linalg.norm(f)
        up = np.array([0.0, 0.0, 1.0])
        s = np.cross(f, up)
        if np.linalg.norm(s) < 1e-8:
            s = np.array([1.0, 0.0, 0.0])
        s /= np.linalg.norm(s)
        u = np.cross(s, f)
        m = np.eye(4)
        m[0, :3], m[1, :3], m[2, :3] = s, u, -f
        m[:3, 3] = -m[:3, :3] @ eye
        return m

    def projection(self, aspect: float) -> np.ndarray:
        t = 1.0 / math.tan(math.radians(self.fov) / 2)
        n, f = self.near, self.far
        m = np.zeros((4, 4))
        m[0, 0], m[1, 1] = t / aspect, t
        m[2, 2], m[2, 3] = (f + n) / (n - f), 2 * f * n / (n - f)
        m[3, 2] = -1.0
        return m

    def orbit(self, d_yaw: float, d_pitch: float) -> None:
        self.yaw = (self.yaw + d_yaw) % 360.0
        self.pitch = float(np.clip(self.pitch + d_pitch, -89.0, 89.0))

    def zoom(self, factor: float) -> None:
        self.distance = float(np.clip(self.distance * factor, 0.3, 50.0))

    def pan(self, dx: float, dy: float) -> None:
        """Moves the target in the image plane by fractions of the distance."""
        v = self.view()
        right, up = v[0, :3], v[1, :3]
        t = np.asarray(self.target, dtype=np.float64) + (-dx * right + dy * up) * self.distance
        self.target = (float(t[0]), float(t[1]), float(t[2]))

    def frame(self, aspect: float = 1.0, radius: float = 1.0) -> None:
        """Centres a normalised object (``radius`` about the origin) and fits it
        into a view of ``aspect`` (w / h) with a margin (``FRAME_FILL``)."""
        self.target = (0.0, 0.0, 0.0)
        self.distance = float(np.clip(framing_distance(self.fov, aspect, radius), 0.3, 50.0))

    def set_fov(self, fov: float) -> None:
        """A new vertical field of view (clamped to ``FOV_RANGE``); the distance
        changes with it so the object keeps its size on screen (a dolly zoom):
        the control changes the perspective, not the framing."""
        new = float(np.clip(fov, *FOV_RANGE))
        old = math.tan(math.radians(self.fov) / 2)
        self.distance = float(np.clip(self.distance * old / math.tan(math.radians(new) / 2), 0.3, 50.0))
        self.fov = new

    def contains(self, points: np.ndarray, aspect: float, margin: float = 0.0) -> bool:
        """Every point (N, 3) projects inside the view, ``margin`` (NDC units) from its edges."""
        p = np.c_[points, np.ones(len(points))] @ (self.projection(aspect) @ self.view()).T
        if (p[:, 3] <= 0).any():
            return False
        ndc = p[:, :2] / p[:, 3:4]
        return bool(np.abs(ndc).max() <= 1.0 - margin)
