"""A 3-D preview of a textured atlas: a small software rasterizer (no display, no GPU).

:func:`render_preview` draws the mesh from a few viewpoints with its texture (the checker by
default), simple shading and the seams, and puts the views side by side in one picture
(``<stem>_preview.png``): one look shows stretch (squares that are not square) and the cuts.

How: every view is a pinhole camera looking at the mesh's bounding sphere. A compiled kernel
(numba, cached on disk like :mod:`segparam.raster`) rasterizes the triangles with a z-buffer
kept in ``1/w`` (the reciprocal camera depth, which is linear in screen space) and stores, per
pixel, the nearest face and its uv interpolated with perspective-correct barycentric
coordinates (screen barycentrics weighted by ``1/w``, renormalised); a second pass looks the
texture up and shades each pixel by its face's light, and a third draws the seams as
depth-tested lines. The three run inside one compiled entry point (one cache load per process).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit

__all__ = [
    "DEFAULT_VIEWS",
    "Camera",
    "camera_for",
    "render_preview",
    "render_view",
    "seam_edges",
]

# (azimuth, elevation) in degrees around the vertical axis (+y, OBJ's and glTF's up): the four
# sides seen a little from above. Four views of 256 px: 20k faces in 0.04-0.12 s (machine
# load 4-6), 0.08-0.13 s in a `segparam atlas` run with the kernel's loading (BENCHMARKS.md
# section 9): within the preview's 0.15 s budget.
DEFAULT_VIEWS: tuple[tuple[float, float], ...] = ((30, 20), (120, 20), (210, 20), (300, 20))
DEFAULT_SIZE = 256
# Camera distance in bounding-sphere radii; the field of view is set so the sphere fills the
# frame with a 5% margin.
CAMERA_DISTANCE = 3.0
MARGIN = 1.05
# Shade = AMBIENT + (1 - AMBIENT) |n . l| with a headlight: dark enough to read the shape, light
# enough to read the texture. Both sides of a face are lit (open meshes show their inside).
AMBIENT = 0.35
BACKGROUND = (250, 250, 250)
SEAM_COLOR = (230, 30, 30)
# A seam pixel is drawn when its 1/w is within this fraction of the z-buffer's (the edge lies
# on the surface it bounds; the tolerance keeps it from being hidden by its own faces).
SEAM_DEPTH_TOLERANCE = 2e-3


class Camera:
    """A pinhole camera: ``eye``, unit ``right``, ``up``, ``forward`` axes, focal length in pixels
    and the image size. A point p is at camera depth ``w = (p - eye) . forward`` and on the screen
    at ``(cx + f x / w, cy - f y / w)`` with ``x, y`` its right/up coordinates (pixel centres at
    half-integers, row 0 at the top)."""

    def __init__(self, eye, right, up, forward, focal: float, size: int):
        self.eye = np.asarray(eye, dtype=np.float64)
        self.right = np.asarray(right, dtype=np.float64)
        self.up = np.asarray(up, dtype=np.float64)
        self.forward = np.asarray(forward, dtype=np.float64)
        self.focal = float(focal)
        self.size = int(size)

    def project(self, P: np.ndarray) -> np.ndarray:
        """(n, 3) points -> (n, 3) rows ``(x_pixel, y_pixel, 1 / w)``."""
        D = np.asarray(P, dtype=np.float64) - self.eye
        w = D @ self.forward
        invw = 1.0 / np.where(w > 1e-12, w, 1e-12)
        c = self.size / 2
        x = c + self.focal * (D @ self.right) * invw
        y = c - self.focal * (D @ self.up) * invw
        return np.stack([x, y, invw], axis=1)


def camera_for(V: np.ndarray, azimuth: float, elevation: float, size: int) -> Camera:
    """The camera of one view: on a sphere of CAMERA_DISTANCE radii around the centre of the
    bounding box, at ``azimuth`` around +y and ``elevation`` above the xz plane (degrees)."""
    V = np.asarray(V, dtype=np.float64)
    centre = (V.min(axis=0) + V.max(axis=0)) / 2
    radius = float(np.sqrt(((V - centre) ** 2).sum(axis=1).max())) or 1.0
    az, el = np.radians(azimuth), np.radians(elevation)
    direction = np.array([np.sin(az) * np.cos(el), np.sin(el), np.cos(az) * np.cos(el)])
    eye = centre + CAMERA_DISTANCE * radius * direction
    forward = -direction
    right = np.cross(forward, [0.0, 1.0, 0.0])
    if np.linalg.norm(right) < 1e-9:  # looking straight down or up
        right = np.array([1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    # the sphere's silhouette subtends asin(1 / d) around the axis
    half = np.arcsin(1.0 / CAMERA_DISTANCE) * MARGIN
    focal = (size / 2) / np.tan(half)
    return Camera(eye, right, up, forward, focal, size)


@njit(cache=True, nogil=True)
def _raster_kernel(S, F, T, invw_buf, face_buf, uv_buf):  # pragma: no cover - compiled
    """Z-buffered rasterization of triangles with screen positions S (x, y, 1/w).

    A pixel centre inside a triangle (edge functions of one sign: both windings are drawn)
    whose interpolated 1/w is larger (nearer) than the buffer's takes the face and the uv
    ``T[t]`` (corner uvs) interpolated with perspective-correct barycentrics
    ``(l_k / w_k) / sum_j (l_j / w_j)``.
    """
    H, W = invw_buf.shape
    for t in range(F.shape[0]):
        a, b, c = F[t, 0], F[t, 1], F[t, 2]
        if S[a, 2] <= 0.0 or S[b, 2] <= 0.0 or S[c, 2] <= 0.0:
            continue
        xa, ya, xb, yb, xc, yc = S[a, 0], S[a, 1], S[b, 0], S[b, 1], S[c, 0], S[c, 1]
        det = (xb - xa) * (yc - ya) - (xc - xa) * (yb - ya)
        if det == 0.0:
            continue
        inv = 1.0 / det
        r0 = max(int(np.ceil(min(ya, yb, yc) - 0.5)), 0)
        r1 = min(int(np.floor(max(ya, yb, yc) - 0.5)), H - 1)
        c0 = max(int(np.ceil(min(xa, xb, xc) - 0.5)), 0)
        c1 = min(int(np.floor(max(xa, xb, xc) - 0.5)), W - 1)
        for r in range(r0, r1 + 1):
            y = r + 0.5
            for q in range(c0, c1 + 1):
                x = q + 0.5
                lb = ((x - xa) * (yc - ya) - (xc - xa) * (y - ya)) * inv
                lc = ((xb - xa) * (y - ya) - (x - xa) * (yb - ya)) * inv
                la = 1.0 - lb - lc
                if la < 0.0 or lb < 0.0 or lc < 0.0:
                    continue
                pa, pb, pc = la * S[a, 2], lb * S[b, 2], lc * S[c, 2]
                iw = pa + pb + pc
                if iw > invw_buf[r, q]:
                    invw_buf[r, q] = iw
                    face_buf[r, q] = t
                    for k in range(2):
                        uv_buf[r, q, k] = (pa * T[t, 0, k] + pb * T[t, 1, k] + pc * T[t, 2, k]) / iw


@njit(cache=True, nogil=True)
def _shade_kernel(face_buf, uv_buf, texture, light, out):  # pragma: no cover - compiled
    """Colour of every drawn pixel: the nearest texel at its uv (picture order: row 0 is v = 1)
    times its face's light; other pixels are left as they are."""
    H, W = face_buf.shape
    th, tw = texture.shape[0], texture.shape[1]
    for r in range(H):
        for q in range(W):
            f = face_buf[r, q]
            if f < 0:
                continue
            col = min(max(int(uv_buf[r, q, 0] * tw), 0), tw - 1)
            row = min(max(int((1.0 - uv_buf[r, q, 1]) * th), 0), th - 1)
            for k in range(3):
                out[r, q, k] = min(texture[row, col, k] * light[f] + 0.5, 255.0)


@njit(cache=True, nogil=True)
def _seam_kernel(S, E, invw_buf, tol, seam_buf):  # pragma: no cover - compiled
    """Mark the pixels of segments E (screen positions S) that are not behind the surface."""
    H, W = invw_buf.shape
    for e in range(E.shape[0]):
        a, b = E[e, 0], E[e, 1]
        if S[a, 2] <= 0.0 or S[b, 2] <= 0.0:
            continue
        dx, dy = S[b, 0] - S[a, 0], S[b, 1] - S[a, 1]
        steps = int(max(abs(dx), abs(dy))) + 1
        for s in range(steps + 1):
            f = s / steps
            x, y = S[a, 0] + f * dx, S[a, 1] + f * dy
            q, r = int(np.floor(x)), int(np.floor(y))
            if r < 0 or r >= H or q < 0 or q >= W:
                continue
            iw = S[a, 2] + f * (S[b, 2] - S[a, 2])
            if iw >= invw_buf[r, q] * (1.0 - tol):
                seam_buf[r, q] = True


@njit(cache=True, nogil=True)
def _render_kernel(S, F, T, light, texture, E, tol, out, seam_mark):  # pragma: no cover
    """One view: rasterize, shade, mark the seams. One compiled entry point, so that a new
    process loads one cached function for the preview instead of three (~0.03 s each)."""
    H, W = seam_mark.shape
    invw = np.zeros((H, W))
    face = np.full((H, W), -1, dtype=np.int64)
    uvs = np.zeros((H, W, 2))
    _raster_kernel(S, F, T, invw, face, uvs)
    _shade_kernel(face, uvs, texture, light, out)
    _seam_kernel(S, E, invw, tol, seam_mark)


def seam_edges(F: np.ndarray, face_uv: np.ndarray) -> np.ndarray:
    """Mesh edges ``(e, 2)`` where the uv map is cut: the boundary edges of the uv triangles,
    as mesh vertex pairs (seams between charts, and the mesh's own borders)."""
    from .mesh import boundary_edges

    F = np.asarray(F, dtype=np.int64)
    face_uv = np.asarray(face_uv, dtype=np.int64)
    uv_vertex = np.zeros(int(face_uv.max()) + 1, dtype=np.int64)
    uv_vertex[face_uv.ravel()] = F.ravel()
    return uv_vertex[boundary_edges(face_uv)].reshape(-1, 2)


def render_view(
    V: np.ndarray,
    F: np.ndarray,
    uv: np.ndarray,
    face_uv: np.ndarray,
    texture: np.ndarray,
    camera: Camera,
    *,
    seams: np.ndarray | None = None,
    shade: bool = True,
    normals: np.ndarray | None = None,
) -> np.ndarray:
    """One view, (size, size, 3) uint8: texture by perspective-correct uv (nearest texel),
    headlight shading by face normal, seams on top; background :data:`BACKGROUND`.

    ``normals`` (m, 3), the unit face normals, may be passed when rendering several views.
    """
    size = camera.size
    # read-only, whatever the caller's: an atlas's faces are, and a writable array would make
    # numba compile the kernel a second time (0.6-1.8 s on a first run) for that flag alone
    F = np.ascontiguousarray(F, dtype=np.int64).view()
    F.flags.writeable = False
    S = np.ascontiguousarray(camera.project(V))
    T = np.ascontiguousarray(np.asarray(uv, dtype=np.float64)[np.asarray(face_uv, dtype=np.int64)])
    if shade:
        from .mesh import face_normals

        N = face_normals(np.asarray(V, dtype=np.float64), F) if normals is None else normals
        light = AMBIENT + (1 - AMBIENT) * np.abs(N @ camera.forward)  # per face
    else:
        light = np.ones(len(F))
    tex = np.ascontiguousarray(texture[..., :3], dtype=np.uint8)
    E = np.zeros((0, 2), np.int64) if seams is None else np.ascontiguousarray(seams, np.int64)
    out = np.empty((size, size, 3), dtype=np.uint8)
    out[:] = BACKGROUND
    mark = np.zeros((size, size), dtype=np.bool_)
    _render_kernel(S, F, T, light, tex, E.reshape(-1, 2), SEAM_DEPTH_TOLERANCE, out, mark)
    out[mark] = SEAM_COLOR
    return out


def render_preview(
    V: np.ndarray,
    F: np.ndarray,
    uv: np.ndarray,
    face_uv: np.ndarray,
    texture: np.ndarray | None = None,
    *,
    seams: np.ndarray | bool = True,
    views: Sequence[tuple[float, float]] = DEFAULT_VIEWS,
    size: int = DEFAULT_SIZE,
    shade: bool = True,
) -> np.ndarray:
    """The mesh with its texture seen from a few viewpoints, side by side.

    Parameters
    ----------
    V, F : (n, 3) float, (m, 3) int ndarrays
        The mesh (an atlas's ``V``, ``F``).
    uv, face_uv : (k, 2) float, (m, 3) int ndarrays
        Texture coordinates (origin bottom-left, as in OBJ) and the uv row of each face corner.
    texture : (h, w, 3) uint8 ndarray, optional
        In picture order (row 0 is v = 1); default the square checker (1024 px; an atlas on a
        trimmed texture passes the checker of its size, ``export.checker_size``).
    seams : bool or (e, 2) int ndarray
        True: draw :func:`seam_edges`; False: none; an array: these mesh edges.
    views : sequence of (azimuth, elevation) degrees
        One view each (:func:`camera_for`); 4 are laid out 2 x 2, otherwise in a row.
    size : int
        Pixels per view side.
    shade : bool
        Headlight shading (False: the texture's colours as they are).

    Returns
    -------
    (H, W, 3) uint8 ndarray
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64).reshape(-1, 3)
    face_uv = np.asarray(face_uv, dtype=np.int64).reshape(-1, 3)
    if texture is None:
        from .export import CHECKER_SIZE, CHECKER_SQUARES, _checker_pixels

        texture = _checker_pixels(CHECKER_SIZE, CHECKER_SQUARES)
    if seams is True:
        seams = seam_edges(F, face_uv)
    elif seams is False:
        seams = None
    images = [
        render_view(
            V, F, uv, face_uv, texture, camera_for(V, az, el, size), seams=seams, shade=shade
        )
        for az, el in views  # a loop over the few views
    ]
    if len(images) == 4:
        return np.vstack([np.hstack(images[:2]), np.hstack(images[2:])])
    return np.hstack(images)
