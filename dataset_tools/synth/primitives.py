"""Analytic surfaces and their ray intersections, vectorised over rays.

Every ``intersect`` takes ray origins and unit directions, both (N, 3) float64, and returns
(t, normal): hit distance (N,) with ``inf`` for a miss, and unit surface normal (N, 3).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

EPS = 1e-6


def _miss(n: int) -> tuple[np.ndarray, np.ndarray]:
    return np.full(n, np.inf), np.zeros((n, 3))


@dataclass(frozen=True)
class Sphere:
    center: tuple[float, float, float]
    radius: float

    def intersect(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        oc = o - np.asarray(self.center)
        b = np.einsum("ij,ij->i", oc, d)
        c = np.einsum("ij,ij->i", oc, oc) - self.radius**2
        disc = b * b - c
        hit = disc >= 0
        t = np.full(len(o), np.inf)
        root = np.sqrt(np.where(hit, disc, 0.0))
        t0, t1 = -b - root, -b + root
        near = np.where(t0 > EPS, t0, t1)
        ok = hit & (near > EPS)
        t[ok] = near[ok]
        p = o + np.where(ok, t, 0.0)[:, None] * d
        return t, (p - np.asarray(self.center)) / self.radius


@dataclass(frozen=True)
class Box:
    """A box of half extents ``half`` centred at ``center``, turned by ``yaw`` about +z."""

    center: tuple[float, float, float]
    half: tuple[float, float, float]
    yaw: float = 0.0

    def _rot(self) -> np.ndarray:
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # local -> world

    def intersect(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rot = self._rot()
        lo = (o - np.asarray(self.center)) @ rot  # world -> local: rot.T @ x
        ld = d @ rot
        ld = np.where(np.abs(ld) < 1e-12, 1e-12, ld)
        h = np.asarray(self.half)
        t1, t2 = (-h - lo) / ld, (h - lo) / ld
        tnear, tfar = np.minimum(t1, t2), np.maximum(t1, t2)
        axis = np.argmax(tnear, axis=1)
        tmin, tmax = tnear.max(axis=1), tfar.min(axis=1)
        ok = (tmax >= tmin) & (tmin > EPS)
        t, n = _miss(len(o))
        t[ok] = tmin[ok]
        local_n = np.zeros((len(o), 3))
        rows = np.arange(len(o))
        local_n[rows, axis] = -np.sign(ld[rows, axis])
        n[ok] = (local_n @ rot.T)[ok]
        return t, n


@dataclass(frozen=True)
class Cylinder:
    """A vertical cylinder standing on ``base`` (centre of its bottom disc)."""

    base: tuple[float, float, float]
    radius: float
    height: float

    def intersect(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        bx, by, bz = self.base
        ox, oy = o[:, 0] - bx, o[:, 1] - by
        a = d[:, 0] ** 2 + d[:, 1] ** 2
        b = ox * d[:, 0] + oy * d[:, 1]
        c = ox**2 + oy**2 - self.radius**2
        disc = b * b - a * c
        a_safe = np.where(a < 1e-12, 1e-12, a)
        t_side = (-b - np.sqrt(np.maximum(disc, 0.0))) / a_safe
        z_side = o[:, 2] + t_side * d[:, 2]
        side_ok = (disc >= 0) & (a > 1e-12) & (t_side > EPS) & (z_side >= bz) & (z_side <= bz + self.height)
        t, n = _miss(len(o))
        t[side_ok] = t_side[side_ok]
        p = o + np.where(side_ok, t_side, 0.0)[:, None] * d
        n[side_ok] = np.stack([p[:, 0] - bx, p[:, 1] - by, np.zeros(len(o))], 1)[side_ok] / self.radius
        dz = np.where(np.abs(d[:, 2]) < 1e-12, 1e-12, d[:, 2])
        for z_cap, nz in ((bz + self.height, 1.0), (bz, -1.0)):
            tc = (z_cap - o[:, 2]) / dz
            pc = o + tc[:, None] * d
            inside = (pc[:, 0] - bx) ** 2 + (pc[:, 1] - by) ** 2 <= self.radius**2
            cap_ok = inside & (tc > EPS) & (tc < t)
            t[cap_ok] = tc[cap_ok]
            n[cap_ok] = (0.0, 0.0, nz)
        return t, n


@dataclass(frozen=True)
class Plane:
    """The plane ``dot(normal, x) = offset``, seen from the side ``normal`` points to."""

    normal: tuple[float, float, float]
    offset: float

    def intersect(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        nrm = np.asarray(self.normal, dtype=np.float64)
        denom = d @ nrm
        with np.errstate(divide="ignore", invalid="ignore"):
            tp = (self.offset - o @ nrm) / denom
        ok = (denom < -1e-9) & (tp > EPS)
        t, n = _miss(len(o))
        t[ok] = tp[ok]
        n[ok] = nrm
        return t, n


Primitive = Sphere | Box | Cylinder | Plane
