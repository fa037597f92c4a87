"""Orbit camera: yaw/pitch/distance around a target; z is up in the world."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass
class OrbitCamera:
    yaw: float = -90.0      # degrees around z; -90 looks along +y
    pitch: float = 20.0     # degrees above the horizon
    distance: float = 3.2
    target: tuple[float, float, float] = (0.0, 0.0, 0.0)
    fov: float = 35.0       # vertical, degrees
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

    def frame(self, radius: float = 1.0) -> None:
        """Centres a normalised object (radius 1 about the origin) in the view."""
        self.target = (0.0, 0.0, 0.0)
        self.distance = radius / math.sin(math.radians(self.fov) / 2) * 1.05

