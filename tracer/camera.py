"""A pinhole camera looking from `origin` at `target` (Mitsuba's look_at).

Image right is cross(forward, up); image row 0 is the top. `fov` is the full field of
view in degrees along `fov_axis` ("x": the image width, "y": the height).
"""
import math
from dataclasses import dataclass, replace

import numpy as np

from ._jit import jit
from .errors import SceneError


@dataclass(frozen=True)
class Camera:
    origin: np.ndarray  # (3,) float64, world space
    forward: np.ndarray  # (3,) unit
    right: np.ndarray  # (3,) unit, image +x
    up: np.ndarray  # (3,) unit, image +y (up on screen)
    tan_x: float  # tan of half the horizontal field of view
    tan_y: float  # tan of half the vertical field of view
    fov: float
    fov_axis: str
    near: float = 0.0  # rays start on the plane this far ahead (Mitsuba's near_clip)

    @staticmethod
    def look_at(origin, target, up, fov, fov_axis, width, height, where="camera"):
        o = np.asarray(origin, dtype=np.float64)
        f = np.asarray(target, dtype=np.float64) - o
        if not np.all(np.isfinite(f)) or np.linalg.norm(f) == 0.0:
            raise SceneError(f"{where}: origin and target must differ")
        f /= np.linalg.norm(f)
        r = np.cross(f, np.asarray(up, dtype=np.float64))
        if np.linalg.norm(r) < 1e-12:
            raise SceneError(f"{where}: 'up' is parallel to the viewing direction")
        r /= np.linalg.norm(r)
        u = np.cross(r, f)
        if not (0.0 < fov < 180.0):
            raise SceneError(f"{where}: fov must be in (0, 180) degrees, got {fov}")
        if fov_axis not in ("x", "y"):
            raise SceneError(f"{where}: fov_axis must be 'x' or 'y', got {fov_axis!r}")
        t = math.tan(math.radians(fov) / 2.0)
        aspect = width / height
        tan_x, tan_y = (t, t / aspect) if fov_axis == "x" else (t * aspect, t)
        return Camera(o, f, r, u, tan_x, tan_y, float(fov), fov_axis)

    @staticmethod
    def from_matrix(matrix, fov, fov_axis, width, height, where="camera"):
        """The camera of a 4x4 camera-to-world matrix in Mitsuba's convention (toWorld): the
        camera at the image of the origin, looking along the image of +z, +y up on screen, +x to
        the image's left (a matrix that mirrors x mirrors the image, as in Mitsuba). Its rotation
        part may be scaled; it must not be singular."""
        m = np.asarray(matrix, dtype=np.float64)
        if m.shape != (4, 4) or not np.all(np.isfinite(m)):
            raise SceneError(f"{where}: expected a finite 4x4 camera-to-world matrix")
        cols = [m[:3, j] for j in range(3)]
        norms = [float(np.linalg.norm(c)) for c in cols]
        if min(norms) < 1e-12 or abs(np.linalg.det(m[:3, :3])) < 1e-12 * norms[0] * norms[1] * norms[2]:
            raise SceneError(f"{where}: the camera-to-world matrix is singular")
        f = cols[2] / norms[2]
        u = cols[1] - np.dot(cols[1], f) * f
        if np.linalg.norm(u) < 1e-12:
            raise SceneError(f"{where}: the camera's up (+y) is parallel to its viewing direction (+z)")
        cam = Camera.look_at(m[:3, 3], m[:3, 3] + f, u, fov, fov_axis, width, height, where=where)
        if np.dot(cam.right, cols[0]) > 0.0:  # a mirrored frame: the image's right is the frame's -x still
            cam = replace(cam, right=-cam.right)
        return cam

    def resized(self, width, height):
        """The same view at another resolution (keeps the fov along fov_axis)."""
        t = self.tan_x if self.fov_axis == "x" else self.tan_y
        aspect = width / height
        tan_x, tan_y = (t, t / aspect) if self.fov_axis == "x" else (t * aspect, t)
        return replace(self, tan_x=tan_x, tan_y=tan_y)

    def packed(self):
        """(13,) float64 for kernels: origin, forward, right*tan_x, up*tan_y, near."""
        return np.concatenate(
            [self.origin, self.forward, self.right * self.tan_x, self.up * self.tan_y, [self.near]]
        ).astype(np.float64)

    def __repr__(self):
        o = np.round(self.origin, 4).tolist()
        f = np.round(self.forward, 4).tolist()
        return f"Camera(origin={o}, forward={f}, fov={self.fov:g} deg along {self.fov_axis})"


@jit
def camera_ray(cam, width, height, px, py, jx, jy):
    """World-space ray through image point (px + jx, py + jy); returns (origin, unit dir). The
    origin is on the near plane (cam[12] ahead; the unnormalised direction has forward part 1)."""
    sx = 2.0 * (px + jx) / width - 1.0
    sy = 1.0 - 2.0 * (py + jy) / height
    dx = cam[3] + sx * cam[6] + sy * cam[9]
    dy = cam[4] + sx * cam[7] + sy * cam[10]
    dz = cam[5] + sx * cam[8] + sy * cam[11]
    inv = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
    near = cam[12]
    return (cam[0] + near * dx, cam[1] + near * dy, cam[2] + near * dz), (dx * inv, dy * inv, dz * inv)
