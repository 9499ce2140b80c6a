"""Pack the charts into the unit square (the pipeline's pack stage).

Every chart arrives mapped bijectively to the plane, at an arbitrary position, scale and rotation.
This stage

1. scales each chart so that its uv area equals its 3-D area (one texel density for the atlas);
2. rotates it to its minimum-area bounding box (rotating calipers on the convex hull);
3. places all charts in the texture square, turned by quarter turns of that frame or (charts
   that are not rectangles) by finer steps, never mirrored, so that the charts' texel footprints
   are `padding` empty texels apart from each other and from the border;
4. maximizes the one global scale for which that placement exists, and reports the utilization;
5. cuts the texture to the rows (columns) the layout uses where an eighth of its side or more
   would be empty (``trim``; the uvs are then u over the width, v over the height: a long
   sheet gets a 1024 x 572 texture it fills, not a square it half fills).

Two methods:

``"raster"`` (default)
    Packs the charts' real shapes: conservative footprints (every texel a triangle touches,
    `segparam.raster`), placed largest first, each where the centroid of its footprint ends up
    lowest, avoiding the placed footprints dilated by `padding`. Two placement rules propose
    positions (`segparam.canvas`, where the texel work of a whole trial is one compiled call):
    ``"rest"`` drops the chart onto the skyline of the placed footprints in ``4 * angle_steps``
    orientations (quarter turns only for rectangles, i.e. charts whose convex hull fills 95% of
    their minimum-area box, and for footprints under `_MIN_TURNING_SIDE` texels); ``"holes"``
    finds the lowest fitting positions anywhere on a coarse grid, also under overhangs and inside
    other charts' concavities, in quarter turns. Round, similar-sized charts (organic surfaces)
    need the fine turns; small charts need the holes. At every scale tried both rules run side by
    side and the layout that needs less height wins.
``"rect"``
    Packs the padded bounding boxes of the footprints with the MaxRects packer of `rectpack`.

The global scale is found by a safeguarded secant search on the height a trial needs (a trial
places every chart on a canvas half again as tall as the texture and reports the height it
used). What was measured, kept and rejected along the way is in BENCHMARKS.md, section 4
(``benchmarks/bench_pack.py``).

Conventions: a texel ``(i, j)`` of a ``resolution x resolution`` texture covers
``[j, j + 1] x [i, i + 1] / resolution`` in uv, i.e. occupancy grids are indexed ``[row = v,
col = u]`` with row 0 at v = 0. A triangle touches a texel when the closed triangle and the closed
texel square intersect.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from numba import njit
from numpy.typing import ArrayLike
from scipy.sparse.csgraph import connected_components

from segparam import canvas
from segparam.errors import (
    ConfigError,
    InvalidMeshError,
    SolverError,
    check_bool,
    check_choice,
    check_int,
    check_number,
)
from segparam.quality import signed_areas
from segparam.raster import footprint_conflicts, rasterize_footprint

__all__ = [
    "PackConfig",
    "PackResult",
    "footprint_conflicts",
    "min_area_rotation",
    "pack_charts",
    "rasterize_footprint",
]

logger = logging.getLogger(__name__)

_METHODS = ("raster", "rect")
#: Largest texture side accepted (texels): the uv-layout image and the packer's canvases grow with
#: its square (16384: a 0.8 GB image).
MAX_RESOLUTION = 16384
# Tolerance (in texels) of the rasterizer used to place charts. It is larger than the one of
# the public `rasterize_footprint`, so that round-off in composing the final affine maps can
# never make a verified footprint larger than the footprint that was packed.
_PACK_EPS = 1e-4
# Each chart is centred in its footprint box with at least this margin (texels) on every side.
_MARGIN = 1e-3
# The "holes" rule searches positions on a grid of about this many cells per side (3 texels a
# cell at 1024), then slides the best ones texel by texel.
_COARSE_CELLS = 342
# Candidate positions of the "holes" rule, per orientation, that are slid and ranked.
_CANDIDATES = 4
# The "rest" rule: lowest resting positions kept per orientation, and the best starting points
# (over all orientations) that are slid and ranked.
_RESTING_PER_ORIENTATION = 2
_RESTING_STARTS = 8
# Footprint columns the resting search tests first at each position (spread over the footprint).
_SKY_SAMPLES = 16
# Most one-texel moves of a slide (down, then left, while the footprint fits).
_SLIDE_STEPS = 1024
# A chart whose convex hull fills at least this much of its minimum-area box is a rectangle for
# the packer: it only turns by quarter turns.
_BOXY = 0.95
# A convex chart whose hull lies between two circles this close (texels at the largest scale a
# search can try) is round for the packer: turned by any angle its footprint moves by less than
# that, so it only turns by quarter turns too. The discs and rings of turned CAD parts (48-gons:
# 0.2% of their radius, 0.6 texels for a 275-texel washer): the bushing of bench_atlas.py packs
# the same layout in 64 instead of 164 ms (BENCHMARKS.md section 0.1, session 20).
_ROUND_TEXELS = 1.0
# Charts of at most this many uv points find their hull and minimum-area box together, by testing
# every directed pair of points (a qhull hull per chart cost 0.26 of the 0.41 s that preparing
# 2,000 triangles took); larger charts get a compiled monotone chain each (`_hulls`).
_SMALL_HULL = 12
# Footprints whose longest side is shorter than this (texels) turn by quarter turns only: at 24,
# 2,000 triangles pack 23% faster and 300 spheres' halves 48% faster, for -0.5 / -0.05 points
# (BENCHMARKS.md, section 4); 48 cost the spheres 1.9 points.
_MIN_TURNING_SIDE = 24
# Placement rules of the raster packer; every trial runs all of them (side by side), and on a
# tie in height the first one wins.
_RULE_ORDER = ("rest", "holes")
_RULE_CODES = {"rest": canvas.REST, "holes": canvas.HOLES}
# A trial's canvas is taller than the texture by 1/_HEADROOM of it, so that an over-full trial
# still places every chart and reports the height it needed (the next guess of the scale).
_HEADROOM = 2
# Scale search (`pack_charts`), a safeguarded secant search on the one global scale (the
# measurements behind each rule, and the variants rejected: BENCHMARKS.md sections 0.1 and 4):
# - the first guess, as a fraction of the area bound of `_scale_bounds` (at the area bound the
#   charts would have to fill the whole square, which no layout of footprints does), or this
#   fraction under the side bound if that is smaller: the longest chart's box then spans the
#   texture's width less a thousandth of a texel at 1024 (the side bound itself is one texel too
#   wide: a box of ``floor(w + 2 * _MARGIN) + 1`` texels);
_FIRST_GUESS = 0.88
_UNDER_SIDE = 1e-6
# - with many charts (at least _MODEL_CHARTS) the first guess is the scale at which the charts,
#   each a square of its area grown by padding + 1 texels, would fill _MODEL_FILL of the texture
#   (`_first_scale`): within 2% of where the search ends on 569-4,000 triangles and sphere
#   pieces (0.88 of the bound was 8-30% too large: 34 -> 21 trials); fewer charts' layouts move
#   too much from one guess to the next for a model (the 50 synthetic charts -1.8 points);
_MODEL_CHARTS = 500
_MODEL_FILL = 0.75
# - the relative precision on the scale at which the bracket [fits, fails] is narrow enough;
#   a guess must also stay half of it inside the bracket, or it is replaced by bisection;
_SCALE_TOL = 0.006
# - the most trials once a layout fits (5 trials cost brain-20k 0.55 points, 4 trials 1.1 points);
_MAX_TRIALS = 6
# - the "full" stop: many charts (at least _SMOOTH_CHARTS) fill the height a trial needs smoothly
#   as the scale grows, so a fit that uses all but _FULL of the texture's side ends the search
#   (2,000 triangles: 3 of 6 trials saved, the same utilization); with fewer charts the height
#   jumps from one scale to the next and a later trial can still fit, so they search on;
_FULL = 0.006
_SMOOTH_CHARTS = 100
# - with fewer charts, a fit that fills the texture is followed by a trial this much larger
#   instead of a bisection towards the last failure, where greedy layouts of few charts rarely
#   fit; the step is just inside `_SCALE_TOL`, so a failure there ends the search (the CAD plate
#   6 -> 2 trials, the bone scan 6 -> 4, the same layouts);
_FULL_STEP = _SCALE_TOL * (1 - 1e-6)
# - a rectangle trial that fails reports only the fraction of the area it placed: the next scale
#   shrinks by its square root, by at least 3% and at most by half;
_SHRINK_LEAST = 0.97
_SHRINK_MOST = 0.5
# - until a layout fits, a guess stays at least 3% under the last scale that failed, so the search
#   always moves down;
_UNDER_FAILED = 0.97
# - except with many charts (at least _MODEL_CHARTS), whose needed height grows smoothly with
#   the scale: there a failed trial before any fit is followed by the secant step aimed at the
#   middle of the "full" window (_AIM of the side), at most just under the failed scale (600-4,000
#   triangles and sphere pieces: 28 -> 22 trials; on ~100 brain charts, whose height jumps, it
#   moved utilization by -0.9 to +1.2 points, so they keep the 3%);
_AIM = 1 - _FULL / 2
# - and with fewer charts after a near miss: a trial that needed at most _NEAR_MISS more of the
#   side than the texture has is followed by the same aimed step, where 3% below it landed on a
#   loose fit and two or three trials climbed back (58 captured chart sets: 251 -> 214 trials,
#   the mean utilization the same);
_NEAR_MISS = 0.02
# - the most trials while no layout fits (each one 3% smaller at least: 60 reach 17% of the first
#   guess), before the SolverError.
_MAX_SHRINK = 60
_RECT_ALGOS = ("MaxRectsBssf",)


@dataclass(frozen=True)
class PackConfig:
    """Options of the packing stage.

    Parameters
    ----------
    resolution : int
        Texels per side of the square the atlas is packed for (the texture, unless `trim` cuts
        it to the rows or columns the layout uses).
    padding : int
        Empty texels kept between the footprints of any two charts and between every footprint
        and the border of the texture.
    method : {"raster", "rect"}
        ``"raster"`` packs the charts' rasterized shapes, ``"rect"`` their bounding boxes.
    rotate : bool
        Allow the charts to turn while packing: by quarter turns (90, 180, 270 degrees), and by
        finer steps in the "rest" placement rule (see `angle_steps`). False keeps every chart
        in its minimum-area frame.
    angle_steps : int
        Rotations per quarter turn that the "rest" rule tries for charts that are not
        rectangles: 6 means steps of 15 degrees; 1 means quarter turns only.
    texels_per_unit : float
        Texel density, texels per unit of 3-D length (xatlas's ``texelsPerUnit``): a 1 x 1
        square takes ``texels_per_unit`` texels a side. 0 (default): the largest density at
        which the charts fit `resolution`. Above 0 the charts are packed at exactly that
        density; with ``resolution = 0`` the resolution follows (the texture grows from the
        charts' area until they fit: :func:`pack_charts`), otherwise the charts must fit
        `resolution` or packing fails with a :class:`SolverError`.
    max_chart_size : int
        Most texels a chart may span (xatlas's ``maxChartSize``: "charts larger than this will
        be scaled down"): a chart whose minimum-area box's longer side would be longer at the
        atlas's density is scaled down to this many texels (it alone gets fewer texels per
        unit). 0 (default): no limit. With ``texels_per_unit = 0`` the density is first found
        without the limit, then the charts above it are scaled down at that density.
    trim : bool
        Cut the texture to the rows (columns) the layout uses when at least `TRIM_LEAST` of its
        side would be empty, rounded up to a multiple of `TRIM_MULTIPLE` texels (default True):
        a long chart (a sheet, a pipe's side) then gets a 1024 x 572 texture rather than a
        square it fills half of; the layout and the texel density are the same either way.
        False: always the square.

    Raises
    ------
    ConfigError
        If a value is out of range.
    """

    resolution: int = 1024
    padding: int = 2
    method: str = "raster"
    rotate: bool = True
    angle_steps: int = 6
    texels_per_unit: float = 0.0
    max_chart_size: int = 0
    trim: bool = True

    def __post_init__(self) -> None:
        # the same checks (and messages) as every stage's config; stored as plain Python values
        object.__setattr__(
            self, "texels_per_unit", check_number("texels_per_unit", self.texels_per_unit, low=0)
        )
        object.__setattr__(
            self, "max_chart_size", check_int("max_chart_size", self.max_chart_size, low=0)
        )
        follows = self.texels_per_unit > 0 and self.resolution == 0  # chosen by the packer
        if self.resolution == 0 and not follows:
            raise ConfigError(
                "resolution is 0; it may be 0 (it follows from the texel density) only with "
                "texels_per_unit above 0"
            )
        low = 0 if follows else 1
        object.__setattr__(self, "resolution", check_int("resolution", self.resolution, low=low))
        if self.resolution > MAX_RESOLUTION:
            raise ConfigError(
                f"resolution is {self.resolution}; it must be at most {MAX_RESOLUTION}, the limit "
                "(the uv picture and the packer's canvases grow with its square)"
            )
        object.__setattr__(self, "padding", check_int("padding", self.padding, low=0))
        object.__setattr__(self, "angle_steps", check_int("angle_steps", self.angle_steps, low=1))
        object.__setattr__(self, "rotate", check_bool("rotate", self.rotate))
        object.__setattr__(self, "trim", check_bool("trim", self.trim))
        check_choice("method", self.method, _METHODS)
        if not follows and self.resolution <= 2 * self.padding:
            raise ConfigError(
                f"resolution {self.resolution} leaves no texel inside a border padding of "
                f"{self.padding} texels on each side"
            )


@dataclass(frozen=True)
class PackResult:
    """The packed atlas.

    Attributes
    ----------
    uvs : tuple of (n_i, 2) float ndarray
        Per chart, the packed uv coordinates, inside ``[padding, width - padding] / width`` in
        u and ``[padding, height - padding] / height`` in v.
    scale : float
        The global factor from 3-D length to uv length along u, ``texels per unit / width``
        (along v it is ``texels per unit / height``): in texels, every chart's area is
        ``(scale * width)**2`` times its 3-D area.
    transforms : (n_charts, 2, 3) float ndarray
        Per chart the affine map ``uv_out = A[:, :2] @ uv_in + A[:, 2]``: a rotation times a
        uniform scale (never a mirror), then u divided by `width` and v by `height`.
    utilization : float
        Total uv triangle area over the area of the unit square: the share of the texture's
        texels (``width x height``) the charts cover.
    resolution : int
        Texels per side of the square the layout was packed for.
    padding : int
        Padding in texels the layout respects at that resolution.
    width, height : int
        The texture's size in texels: ``resolution`` each, or less where the layout was trimmed
        (``PackConfig.trim``). A uv ``(u, v)`` is the texel point ``(u * width, v * height)``.
    """

    uvs: tuple[np.ndarray, ...]
    scale: float
    transforms: np.ndarray
    utilization: float
    resolution: int
    padding: int
    width: int = 0
    height: int = 0

    def __post_init__(self) -> None:
        # an unset size is the square the layout was packed for
        if self.width == 0:
            object.__setattr__(self, "width", self.resolution)
        if self.height == 0:
            object.__setattr__(self, "height", self.resolution)

    @property
    def size(self) -> tuple[int, int]:
        """The texture's ``(width, height)`` in texels."""
        return (self.width, self.height)

    @property
    def texels_per_unit(self) -> float:
        """Texels per unit of 3-D length, the same along u and v."""
        return self.scale * self.width

    def isotropic(self, uv: np.ndarray) -> np.ndarray:
        """``uv`` with v times ``height / width``: texels of one size along u and v, u still
        over [0, 1] (``uv`` itself on a square texture). Lengths and angles there are the
        texture's: distortion is measured, and the flat GIfTI surface laid out, on these."""
        return uv * np.array([1.0, self.height / self.width])


@dataclass(frozen=True)
class _Chart:
    """A validated chart in its canonical frame (private; trusted by the kernels)."""

    index: int
    uv: np.ndarray  # (n, 2) the input coordinates
    q: np.ndarray  # (n, 2) rotated, scaled to 3-D units, min corner at the origin
    F: np.ndarray  # (m, 3) faces, counter-clockwise in q
    extent: np.ndarray  # (2,) width and height of q's bounding box, 3-D units
    to_q: np.ndarray  # (3, 3) affine map from the input uv to q
    area: float  # 3-D area (= uv area of q)
    boxy: bool  # its convex hull nearly fills its minimum-area box (turns by quarter turns only)
    boundary: np.ndarray | None  # (k, 2) directed boundary edges for `_fill_kernel`, or None
    # convex, between circles of radii r and r + roundness (3-D units) about its hull's centroid
    # (infinite if not, or not measured): see `_ROUND_TEXELS`
    roundness: float = np.inf


# ----------------------------------------------------------------------------------------------
# geometry helpers


def min_area_rotation(uv: np.ndarray) -> tuple[np.ndarray, float]:
    """Rotate a point set so that its minimum-area bounding box is axis-aligned.

    Rotating calipers: the minimum-area enclosing rectangle has a side collinear with an edge
    of the convex hull, so every hull edge direction is tried. Of the optimal boxes the one
    that comes out wider than tall is returned (ties broken by the first hull edge).

    Parameters
    ----------
    uv : (n, 2) float ndarray
        Points, n >= 3, not all collinear.

    Returns
    -------
    rotated : (n, 2) float ndarray
        ``uv @ R.T`` with ``R`` the rotation by `angle` about the origin.
    angle : float
        The counter-clockwise rotation applied, in radians, in ``(-pi, pi]``.

    Raises
    ------
    InvalidMeshError
        If `uv` is not an (n, 2) finite array or its points span no area.
    """
    uv = np.asarray(uv, dtype=np.float64)
    if uv.ndim != 2 or uv.shape[1] != 2 or uv.shape[0] < 3:
        raise InvalidMeshError(f"uv must be an (n, 2) array with n >= 3, got shape {uv.shape}")
    if not np.all(np.isfinite(uv)):
        raise InvalidMeshError("uv has non-finite coordinates")
    angle, _ = _min_area_angle(uv)
    return uv @ _rotation(angle).T, angle


def _rotation(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


def _min_area_angle(uv: np.ndarray) -> tuple[float, float]:
    """The rotation that makes the minimum-area box axis-aligned, and the hull's fill of that box.

    The fill (convex hull area / box area, 1 for a rectangle) is what tells the packer that a
    chart is a rectangle.
    """
    angle, fill = _hull_boxes([uv])
    return float(angle[0]), float(fill[0])


def _boxes_along(
    P: np.ndarray, theta: np.ndarray, valid: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per point set ``P[c]`` (c, n, 2), the best of the boxes aligned with the directions
    ``theta[c]`` (c, d) where ``valid``: the turn that makes it axis-aligned and wider than tall
    (in ``(-pi, pi]``), and its area.

    Turning by ``-theta`` makes a direction horizontal; the points are projected on both axes
    at once. The argmin is tolerant (the first direction within 1e-12 of the least area), so
    that symmetric shapes pick the same direction on every platform.
    """
    c, s = np.cos(theta), np.sin(theta)
    x = c[..., None] * P[:, None, :, 0] + s[..., None] * P[:, None, :, 1]
    y = -s[..., None] * P[:, None, :, 0] + c[..., None] * P[:, None, :, 1]
    w, h = np.ptp(x, axis=2), np.ptp(y, axis=2)
    box = np.where(valid, w * h, np.inf)
    least = box.min(axis=1)
    best = np.argmax(box <= least[:, None] * (1 + 1e-12), axis=1)
    rows = np.arange(len(P))
    angle = -theta[rows, best] + np.where(h[rows, best] > w[rows, best], np.pi / 2, 0.0)
    return np.arctan2(np.sin(angle), np.cos(angle)), least


# ----------------------------------------------------------------------------------------------
# validation and canonical frames


def _prepare(
    uvs: Sequence[np.ndarray], faces: Sequence[np.ndarray], areas3d: ArrayLike
) -> list[_Chart]:
    """Validate the charts and put each in its canonical frame, all charts at once.

    Per chart: uv area scaled to the 3-D area, turned to the minimum-area box, minimum corner
    at the origin, faces counter-clockwise, and the outline for the fill rasterizer when every
    triangle is counter-clockwise. The only loops are over charts for their shapes and, for
    charts of more than `_SMALL_HULL` points, their convex hulls.
    """
    if len(uvs) == 0:
        raise InvalidMeshError("no charts to pack (empty list)")
    if len(faces) != len(uvs):
        raise InvalidMeshError(f"got {len(uvs)} uv arrays but {len(faces)} face arrays")
    areas = np.asarray(areas3d, dtype=np.float64).reshape(-1)
    if areas.shape[0] != len(uvs):
        raise InvalidMeshError(f"got {len(uvs)} charts but {areas.shape[0]} 3-D areas")
    uv_list, F_list = [], []
    for i, (uv, F) in enumerate(zip(uvs, faces, strict=True)):  # loop over charts: shapes
        uv = np.asarray(uv, dtype=np.float64)
        F = np.asarray(F)
        if uv.ndim != 2 or uv.shape[1] != 2 or uv.shape[0] < 3:
            raise InvalidMeshError(f"chart {i}: uv must be (n, 2) with n >= 3, got {uv.shape}")
        if F.ndim != 2 or F.shape[1] != 3 or F.shape[0] == 0:
            raise InvalidMeshError(f"chart {i}: faces must be (m, 3) with m >= 1, got {F.shape}")
        if F.dtype.kind not in "iu":  # np.issubdtype(F.dtype, np.integer), 10x cheaper
            raise InvalidMeshError(f"chart {i}: faces must be integers, got dtype {F.dtype}")
        uv_list.append(uv)
        F_list.append(F)
    n = len(uv_list)
    nv = np.array([len(u) for u in uv_list])
    nf = np.array([len(f) for f in F_list])
    voff = np.r_[0, np.cumsum(nv)[:-1]]
    foff = np.r_[0, np.cumsum(nf)[:-1]]
    U = np.concatenate(uv_list)
    Fl = np.concatenate(F_list).astype(np.int64)  # local indices
    vchart = np.repeat(np.arange(n), nv)
    fchart = np.repeat(np.arange(n), nf)

    def first(bad: np.ndarray) -> int:
        return int(np.flatnonzero(bad)[0])

    bad = np.bincount(vchart, ~np.isfinite(U).all(axis=1), minlength=n) > 0
    if bad.any():
        raise InvalidMeshError(f"chart {first(bad)}: uv has non-finite coordinates")
    fmin = np.minimum.reduceat(Fl.min(axis=1), foff)
    fmax = np.maximum.reduceat(Fl.max(axis=1), foff)
    bad = (fmin < 0) | (fmax >= nv)
    if bad.any():
        i = first(bad)
        raise InvalidMeshError(
            f"chart {i}: face indices span [{fmin[i]}, {fmax[i]}] but uv has {nv[i]} rows"
        )
    bad = ~np.isfinite(areas) | ~(areas > 0)
    if bad.any():
        i = first(bad)
        raise InvalidMeshError(
            f"chart {i} has 3-D area {float(areas[i])}; every chart needs a positive one"
        )
    G = Fl + voff[fchart][:, None]  # faces into U
    signed = signed_areas(U, G)
    area_uv = np.bincount(fchart, np.abs(signed), minlength=n)
    span = (np.maximum.reduceat(U, voff) - np.minimum.reduceat(U, voff)).max(axis=1)
    bad = ~(area_uv > 1e-14 * span * span)
    if bad.any():
        i = first(bad)
        raise InvalidMeshError(
            f"chart {i} has uv area {area_uv[i]:.3g} (bounding box {span[i]:.3g}); it must be "
            "mapped to the plane with a positive area"
        )
    angle, fill, hull_area, gap, radius = _min_area_angles(U, nv, voff)
    k = np.sqrt(areas / area_uv)
    c, s = np.cos(angle), np.sin(angle)
    cv, sv = c[vchart], s[vchart]
    r = np.column_stack([cv * U[:, 0] - sv * U[:, 1], sv * U[:, 0] + cv * U[:, 1]])
    low = np.minimum.reduceat(r, voff)
    Q = (r - low[vchart]) * k[vchart, None]
    extent = np.maximum.reduceat(Q, voff)
    to_q = np.zeros((n, 3, 3))
    to_q[:, 0, 0], to_q[:, 0, 1], to_q[:, 1, 0], to_q[:, 1, 1] = k * c, -k * s, k * s, k * c
    to_q[:, :2, 2] = -k[:, None] * low
    to_q[:, 2, 2] = 1.0
    flip = (np.bincount(fchart, signed, minlength=n) < 0)[fchart]  # keep the faces ccw
    G[flip] = G[flip][:, [0, 2, 1]]
    # the outline rasterizer needs every triangle counter-clockwise (no flip, no sliver)
    ccw = np.bincount(fchart, signed_areas(Q, G) <= 0, minlength=n) == 0
    outlines = _outlines(G, fchart, voff, ccw, len(U))
    roundness = _roundness(Q, voff, outlines, hull_area * k * k, gap * k, radius * k)
    return [
        _Chart(
            i,
            uv_list[i],
            Q[voff[i] : voff[i] + nv[i]],
            G[foff[i] : foff[i] + nf[i]] - voff[i],
            extent[i],
            to_q[i],
            float(areas[i]),
            bool(fill[i] >= _BOXY),
            outlines[i],
            float(roundness[i]),
        )  # fmt: skip
        for i in range(n)  # loop over charts: views into the arrays above
    ]


def _min_area_angles(U: np.ndarray, nv: np.ndarray, voff: np.ndarray):
    """`_min_area_angle` of every chart's points ``U[voff[i] : voff[i] + nv[i]]``: (angles,
    fills), and for the charts of more than `_SMALL_HULL` points their hulls' areas, ring gaps
    and radii (`_hull_boxes`' ``rings``; NaN, infinite and 0 for the others).

    Charts of up to `_SMALL_HULL` points are done together, a group per point count: a directed
    pair (i, j) is a hull edge when no point lies right of it and the points on its line lie
    between i and j, which gives the hull without qhull; the boxes of the hull edges' directions
    are measured by `_boxes_along`, as in `_min_area_angle`. Larger charts get their hulls and
    boxes together (`_hull_boxes`).
    """
    n = len(nv)
    angle, fill = np.zeros(n), np.zeros(n)
    hull_area, gap, radius = np.full(n, np.nan), np.full(n, np.inf), np.zeros(n)
    for size in np.unique(nv[nv <= _SMALL_HULL]):  # loop over the few small point counts
        idx = np.flatnonzero(nv == size)
        P = U[voff[idx][:, None] + np.arange(size)]  # (c, n, 2)
        P = P - P.mean(axis=1, keepdims=True)
        ii, jj = np.nonzero(~np.eye(size, dtype=bool))  # directed pairs
        d = P[:, jj] - P[:, ii]  # (c, pairs, 2)
        rel = P[:, None, :, :] - P[:, ii][:, :, None, :]  # (c, pairs, n, 2)
        cross = d[..., None, 0] * rel[..., 1] - d[..., None, 1] * rel[..., 0]
        along = (rel * d[:, :, None, :]).sum(-1)
        length2 = (d * d).sum(-1)
        between = (along >= 0) & (along <= length2[..., None])
        hull = ((cross > 0) | ((cross == 0) & between)).all(axis=2) & (length2 > 0)
        area = 0.5 * np.where(hull, P[:, ii, 0] * P[:, jj, 1] - P[:, ii, 1] * P[:, jj, 0], 0)
        area = area.sum(axis=1)
        theta = np.arctan2(d[..., 1], d[..., 0])
        a, best_area = _boxes_along(P, theta, hull)
        if not np.all(area > 0) or not np.all(np.isfinite(best_area)):
            bad = idx[~(area > 0) | ~np.isfinite(best_area)][0]
            raise InvalidMeshError(
                f"chart {bad}: chart uv points span no area ({size} points are collinear or "
                "coincide)"
            )
        angle[idx] = a
        fill[idx] = area / best_area
    large = np.flatnonzero(nv > _SMALL_HULL)
    if len(large):
        angle[large], fill[large], hull_area[large], gap[large], radius[large] = _hull_boxes(
            [U[voff[i] : voff[i] + nv[i]] for i in large], large, rings=True
        )
    return angle, fill, hull_area, gap, radius


def _hull_boxes(
    points: list[np.ndarray], ids: np.ndarray | None = None, *, rings: bool = False
) -> tuple[np.ndarray, ...]:
    """`_min_area_angle` of several point sets: their convex hulls all at once (`_hulls`), then
    the boxes of all hulls' edge directions in one `_boxes_along` call (hulls padded with their
    first vertex, whose directions are not valid). The same angles and fills as one
    `_min_area_angle` per set. `ids` name the sets (charts) in errors. With `rings`, also each
    hull's area and the two circles about its centroid that it lies between: the farthest
    vertex's distance, and how much nearer the nearest edge's line comes (`_ROUND_TEXELS`).

    A qhull hull per set (scipy's ``ConvexHull``) cost 0.15 ms each, 0.18 s of the 0.26 s that
    preparing 300 spheres' 1,203 charts took; a hull now starts at its lowest-leftmost vertex, so
    a symmetric chart's tie between equal boxes no longer depends on where qhull started.
    """
    sizes = np.array([len(uv) for uv in points])
    ptr = np.r_[0, np.cumsum(sizes)]
    which = np.repeat(np.arange(len(points)), sizes)
    U = np.concatenate(points).astype(np.float64, copy=False)
    centred = U - (np.add.reduceat(U, ptr[:-1]) / sizes[:, None])[which]
    order = np.lexsort((centred[:, 1], centred[:, 0], which))  # per set, by x then y
    S = centred[order]
    index, count = _hulls(S, ptr)
    H = S[index]  # every hull, counter-clockwise, padded to its set's size
    start = ptr[:-1]
    x, y = H[:, 0], H[:, 1]
    slot = np.arange(len(H)) - start[which]
    nxt = np.where(slot + 1 < count[which], np.arange(len(H)) + 1, start[which])
    in_hull = slot < count[which]  # the rows past a hull's count repeat its vertices
    cross = np.where(in_hull, x * y[nxt] - x[nxt] * y, 0)
    # each hull's own terms, summed in order: a padded row's sum (pairwise over the widest
    # hull) would differ in the last bit from the hull's alone, and the boxes must not depend
    # on the batch
    area = 0.5 * np.add.reduceat(cross, start)
    bad = (count < 3) | ~(area > 0)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        where = "" if ids is None else f"chart {ids[k]}: "
        raise InvalidMeshError(
            f"{where}chart uv points span no area ({sizes[k]} points are collinear or coincide)"
        )
    hmax = int(count.max())
    slot = np.arange(hmax)
    valid = slot[None, :] < count[:, None]
    P = H[start[:, None] + np.where(valid, slot[None, :], 0)]  # (c, hmax, 2), padded
    d = H[start[:, None] + (slot[None, :] + 1) % count[:, None]] - P  # edge k: vertex k -> k+1
    theta = np.arctan2(d[..., 1], d[..., 0])
    angle, box = _boxes_along(P, theta, valid)
    if not rings:
        return angle, area / box
    # the centroid of each hull polygon, then its farthest vertex and its nearest edge's line
    cx = np.add.reduceat((x + x[nxt]) * cross, start) / (6 * area)
    cy = np.add.reduceat((y + y[nxt]) * cross, start) / (6 * area)
    dx, dy = x - cx[which], y - cy[which]
    ex, ey = x[nxt] - x, y[nxt] - y
    line = np.abs(ex * dy - ey * dx) / np.maximum(np.hypot(ex, ey), 1e-300)
    radius = np.maximum.reduceat(np.where(in_hull, np.hypot(dx, dy), 0.0), start)
    nearest = np.minimum.reduceat(np.where(in_hull, line, np.inf), start)
    return angle, area / box, area, radius - nearest, radius


@njit(cache=True, nogil=True)
def _turn(S: np.ndarray, o: int, p: int, q: int) -> float:  # pragma: no cover - compiled
    """Twice the signed area of the triangle (o, p, q) of points of `S`: > 0 for a left turn."""
    return (S[p, 0] - S[o, 0]) * (S[q, 1] - S[o, 1]) - (S[p, 1] - S[o, 1]) * (S[q, 0] - S[o, 0])


@njit(cache=True, nogil=True)
def _hulls(S: np.ndarray, ptr: np.ndarray):  # pragma: no cover - compiled
    """Convex hulls of the point sets ``S[ptr[c]:ptr[c + 1]]``, each sorted by x then y
    (Andrew's monotone chain; points on an edge are not vertices): per set, its hull's vertex
    indices into `S`, counter-clockwise from the first point, written from ``ptr[c]`` on (the
    rest of its slots repeat them), and its vertex count."""
    n_sets = len(ptr) - 1
    index = np.empty(len(S), dtype=np.int64)
    count = np.zeros(n_sets, dtype=np.int64)
    stack = np.empty(2 * len(S) + 1, dtype=np.int64)
    for c in range(n_sets):
        a, b = ptr[c], ptr[c + 1]
        k = 0
        for i in range(a, b):  # the lower chain, left to right
            while k >= 2 and _turn(S, stack[k - 2], stack[k - 1], i) <= 0:
                k -= 1
            stack[k] = i
            k += 1
        lower = k + 1
        for i in range(b - 2, a - 1, -1):  # the upper chain, right to left
            while k >= lower and _turn(S, stack[k - 2], stack[k - 1], i) <= 0:
                k -= 1
            stack[k] = i
            k += 1
        k = max(k - 1, 1)  # the last point is the first
        count[c] = k
        for j in range(b - a):
            index[a + j] = stack[j % k]
    return index, count


def _outlines(G: np.ndarray, fchart: np.ndarray, voff: np.ndarray, ok: np.ndarray, n_points: int):
    """`segparam.raster.boundary_edges` of every chart whose `ok` is set (None for the others
    and where the fill cannot use the outline), local indices, all charts in one pass."""
    n = len(voff)
    E = np.concatenate([G[:, [0, 1]], G[:, [1, 2]], G[:, [2, 0]]])  # per chart: 01, 12, 20
    echart = np.tile(fchart, 3)
    # One sort by undirected edge (two np.unique calls took 0.75 s at 1M faces, this 0.46 s):
    # a run of one is a boundary edge; an edge of 3+ faces, or of two that run it the same way
    # (adjacent in the run, same first vertex), is not a valid outline.
    undirected = np.minimum(E[:, 0], E[:, 1]) * n_points + np.maximum(E[:, 0], E[:, 1])
    order = np.argsort(undirected, kind="stable")
    u = undirected[order]
    start = np.r_[True, u[1:] != u[:-1]]
    run = np.cumsum(start) - 1
    count_u = np.empty(len(E), dtype=np.int64)
    count_u[order] = np.bincount(run)[run]
    tail = E[order, 0]
    twice = ~start[1:] & (tail[1:] == tail[:-1])
    bad_edge = count_u > 2
    bad_edge[order[1:][twice]] = True
    bad_edge[order[:-1][twice]] = True
    ok = ok & (np.bincount(echart, bad_edge, minlength=n) == 0)
    keep = (count_u == 1) & ok[echart]
    order = np.argsort(echart[keep], kind="stable")
    B, bchart = E[keep][order], echart[keep][order]
    bounds = np.searchsorted(bchart, np.arange(n + 1))
    return [
        (B[bounds[i] : bounds[i + 1]] - voff[i]) if ok[i] else None for i in range(n)
    ]  # loop over charts: slices


def _roundness(
    Q: np.ndarray,
    voff: np.ndarray,
    outlines: list,
    hull_area: np.ndarray,
    gap: np.ndarray,
    radius: np.ndarray,
) -> np.ndarray:
    """Per chart, the width of the ring its hull lies in (`_hull_boxes`' ``rings``, 3-D units)
    where the chart is convex (its outer boundary loop encloses its whole hull, to 1e-9 of its
    area: holes allowed), else infinite (`_ROUND_TEXELS`). Only charts whose ring is within 2%
    of their radius, with an outline (`_outlines`), have their loops measured: a loop over
    those few (the discs and rings of CAD parts)."""
    out = np.full(len(voff), np.inf)
    for i in np.flatnonzero(gap <= 0.02 * radius).tolist():  # loop over the round ones: a few
        B = outlines[i]
        if B is None:
            continue
        q = Q[voff[i] :]
        _, loop = connected_components(
            sp.coo_matrix((np.ones(len(B)), (B[:, 0], B[:, 1])), shape=(B.max() + 1,) * 2),
            directed=True,
            connection="weak",
        )
        twice = q[B[:, 0], 0] * q[B[:, 1], 1] - q[B[:, 1], 0] * q[B[:, 0], 1]
        enclosed = 0.5 * np.bincount(loop[B[:, 0]], weights=twice).max()  # the outer loop's
        if enclosed >= hull_area[i] * (1 - 1e-9):
            out[i] = gap[i]
    return out


# ----------------------------------------------------------------------------------------------
# footprints at a given scale


def _box(extent: np.ndarray, s: float) -> tuple[np.ndarray, np.ndarray]:
    """Footprint box size (texels, integers) and the chart's offset that centres it (one
    extent ``(2,)`` or many ``(n, 2)``)."""
    w = extent * s
    n = np.floor(w + 2 * _MARGIN).astype(np.int64) + 1
    return n, (n - w) / 2


def _turns(k: np.ndarray, cols: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(n, 3, 3) affines of ``k`` counter-clockwise quarter turns of the boxes [0, cols] x
    [0, rows] (one per chart)."""
    k = np.asarray(k) % 4
    T = np.zeros((len(k), 3, 3))
    T[:, 2, 2] = 1.0
    c, r = np.asarray(cols, dtype=np.float64), np.asarray(rows, dtype=np.float64)
    # k = 0: the identity; 1: (x, y) -> (rows - y, x); 2: (cols - x, rows - y); 3: (y, cols - x)
    T[:, 0, 0] = np.select([k == 0, k == 2], [1.0, -1.0], 0.0)
    T[:, 1, 1] = T[:, 0, 0]
    T[:, 0, 1] = np.select([k == 1, k == 3], [-1.0, 1.0], 0.0)
    T[:, 1, 0] = -T[:, 0, 1]
    T[:, 0, 2] = np.select([k == 1, k == 2], [r, c], 0.0)
    T[:, 1, 2] = np.select([k == 2, k == 3], [r, c], 0.0)
    return T


class _Angles:
    """Every chart in every orientation angle the packer tries, flattened for `canvas.trial`.

    Built once per `pack_charts` call (scale-free but for the round charts' test at the largest
    scale). Per chart and angle (``a * 90 / steps`` degrees from the minimum-area frame, ``steps
    = angles`` unless the chart is a rectangle or round): the chart's points turned by the angle
    with their minimum corner at the origin (3-D units), their extent, and the rotation and
    offset that map them back. It also keeps, for the packing it serves, the empty trial canvas
    of each texture size (`empty_canvas`).
    """

    def __init__(self, charts: list[_Chart], angles: int, scale: float = np.inf) -> None:
        n = len(charts)
        nv = np.array([len(ch.q) for ch in charts])
        # rectangles, and round charts at every scale up to `scale`: quarter turns only
        quarter = [ch.boxy or ch.roundness * scale <= _ROUND_TEXELS for ch in charts]
        steps = np.where(quarter, 1, angles)
        self.entry_ptr = np.r_[0, np.cumsum(steps)].astype(np.int64)
        e_chart = np.repeat(np.arange(n), steps)
        e_angle = (np.arange(len(e_chart)) - self.entry_ptr[e_chart]) * np.pi / (2 * steps[e_chart])
        c, s = np.cos(e_angle), np.sin(e_angle)
        self.rot = np.stack([np.stack([c, -s], 1), np.stack([s, c], 1)], 1)  # (entries, 2, 2)
        # every entry's points: its chart's q turned by the entry's angle (angle 0: q itself)
        Q = np.concatenate([ch.q for ch in charts])
        voff = np.r_[0, np.cumsum(nv)[:-1]]
        e_n = nv[e_chart]
        self.q_ptr = np.r_[0, np.cumsum(e_n)].astype(np.int64)
        rows = np.repeat(voff[e_chart] - self.q_ptr[:-1], e_n) + np.arange(self.q_ptr[-1])
        x, y = Q[rows, 0], Q[rows, 1]
        pc, ps = np.repeat(c, e_n), np.repeat(s, e_n)
        turned = np.repeat(e_angle, e_n) != 0
        r = np.column_stack(
            [np.where(turned, pc * x - ps * y, x), np.where(turned, ps * x + pc * y, y)]
        )
        self.low = np.minimum.reduceat(r, self.q_ptr[:-1])
        self.ext = np.ascontiguousarray(np.maximum.reduceat(r, self.q_ptr[:-1]) - self.low)
        self.Q = np.ascontiguousarray(r - np.repeat(self.low, e_n, axis=0))
        # elements: the outline (edges as (a, b, b)) where the fill can use it, else triangles
        elems = [
            ch.F if ch.boundary is None else ch.boundary[:, [0, 1, 1]] for ch in charts
        ]  # loop over charts: views
        self.el_ptr = np.r_[0, np.cumsum([len(e) for e in elems])].astype(np.int64)
        self.elems = np.ascontiguousarray(np.concatenate(elems), dtype=np.int64)
        self.fill = np.array([ch.boundary is not None for ch in charts], dtype=np.bool_)
        self._canvases: dict[tuple[int, int, int], tuple] = {}

    def empty_canvas(self, resolution: int, padding: int, block: int) -> tuple:
        """The empty trial canvas (texture width, `_HEADROOM` taller), built once per size and
        packing: every trial starts from a copy (building it cost 2 of a 3-chart trial's
        ~30 ms). It lives as long as this object, so a large texture's canvas is not kept
        after the packing."""
        key = (resolution, padding, block)
        if key not in self._canvases:
            height = resolution + resolution // _HEADROOM
            self._canvases[key] = canvas.new_canvas(resolution, height, padding, block)
        return self._canvases[key]

    def to_texels(self, a: np.ndarray, k: np.ndarray, s: float) -> np.ndarray:
        """(n, 3, 3) affines from every chart's q to its footprint's texels: chart i at angle
        ``a[i]`` and ``k[i]`` quarter turns."""
        e = self.entry_ptr[:-1] + a
        n, off = _box(self.ext[e], s)
        to_tex = np.zeros((len(e), 3, 3))
        to_tex[:, :2, :2] = s * self.rot[e]
        to_tex[:, :2, 2] = off - s * self.low[e]
        to_tex[:, 2, 2] = 1.0
        return _turns(k, n[:, 0], n[:, 1]) @ to_tex


#: A layout: per chart (input order), the affine from its q to its footprint's texels (n, 3, 3),
#: and the footprint's row and column in the texture (n,) each.
_Placed = tuple[np.ndarray, np.ndarray, np.ndarray]


def _raster_trial(
    charts: list[_Chart],
    order: np.ndarray,
    s: float,
    resolution: int,
    padding: int,
    turns: int,
    rule: str,
    angles: _Angles,
) -> tuple[_Placed | None, float, int | None]:
    """Place all charts at scale s on a canvas half again as tall as the texture, by one rule.

    The "rest" rule tries every angle of `angles` (fine steps for the charts that are not
    rectangles); the "holes" rule tries quarter turns only. One compiled call
    (`canvas.trial`).

    Returns
    -------
    placed : ((n, 3, 3) q -> footprint texel affines, (n,) rows, (n,) columns), or None
        Per chart, in input order; None if a chart found no room even on the taller canvas.
    fraction : float
        Fraction of the total area placed.
    need : int or None
        Texture side the layout needs (top-most footprint row + 1 + padding); the layout is
        valid for the texture when ``need <= resolution``.
    """
    block = max(1, -(-resolution // _COARSE_CELLS))
    n_placed, result, need = canvas.trial(
        angles.Q, angles.q_ptr, angles.ext, angles.elems, angles.el_ptr, angles.fill,
        angles.entry_ptr, np.asarray(order, dtype=np.int64), float(s),
        angles.empty_canvas(int(resolution), int(padding), block), int(padding), int(turns),
        _RULE_CODES[rule], block, _MARGIN, _PACK_EPS,
        _RESTING_PER_ORIENTATION, _RESTING_STARTS, _CANDIDATES, _SKY_SAMPLES, _SLIDE_STEPS,
        _MIN_TURNING_SIDE,
    )  # fmt: skip
    if n_placed < len(order):
        done = sum(charts[i].area for i in order[:n_placed])
        return None, done / sum(ch.area for ch in charts), None
    a, k, row, col = result[:, 0], result[:, 1], result[:, 2], result[:, 3]
    return (angles.to_texels(a, k, s), row, col), 1.0, int(need)


# ----------------------------------------------------------------------------------------------
# rectangle packer


def _rect_trial(
    charts: list[_Chart],
    order: np.ndarray,
    s: float,
    resolution: int,
    padding: int,
    turns: int,
    rule: str = "boxes",
    angles: _Angles | None = None,
) -> tuple[_Placed | None, float, int | None]:
    """Pack the padded footprint boxes at scale s with rectpack's MaxRects.

    Boxes are ``(cols + padding, rows + padding)`` in a bin of side ``resolution - padding``
    whose origin is at texel ``(padding, padding)``, which leaves `padding` texels between
    footprints and to the border. Boxes turn by a quarter turn when ``turns > 1`` (boxes of
    the minimum-area frame; `angles` is not used). Same return values as `_raster_trial`.
    """
    try:
        import rectpack
    except ImportError as exc:  # optional dependency, only for this method
        raise ConfigError(
            'method="rect" needs the rectpack package (pip install rectpack)'
        ) from exc

    bin_side = resolution - padding
    boxes = [_box(ch.extent, s)[0] + padding for ch in charts]
    total = sum(ch.area for ch in charts)
    done = 0.0
    for name in _RECT_ALGOS:
        packer = rectpack.newPacker(
            mode=rectpack.PackingMode.Offline,
            bin_algo=rectpack.PackingBin.BFF,
            pack_algo=getattr(rectpack, name),
            sort_algo=rectpack.SORT_NONE,
            rotation=turns > 1,
        )
        packer.add_bin(bin_side, bin_side, count=1)
        for i in order:
            packer.add_rect(int(boxes[i][0]), int(boxes[i][1]), rid=int(i))
        packer.pack()
        rects = packer.rect_list()
        if len(rects) != len(charts):
            done = max(done, sum(charts[r[5]].area for r in rects))
            continue
        rid = np.array([r[5] for r in rects])
        x, y, w = (np.array([r[k] for r in rects])[np.argsort(rid)] for k in (1, 2, 3))
        n, off = _box(np.array([ch.extent for ch in charts]), s)
        to_tex = np.zeros((len(charts), 3, 3))
        to_tex[:, [0, 1, 2], [0, 1, 2]] = [s, s, 1.0]
        to_tex[:, :2, 2] = off
        turned = w != np.array(boxes)[:, 0]  # rectpack turned the box
        to_tex = _turns(turned.astype(np.int64), n[:, 0], n[:, 1]) @ to_tex
        return (to_tex, y + padding, x + padding), 1.0, None
    return None, done / total, None


# ----------------------------------------------------------------------------------------------
# driver


def _scale_bounds(charts: list[_Chart], resolution: int, padding: int) -> tuple[float, float]:
    """Two bounds on the scale: at ``by_area`` the charts' area fills the whole square inside the
    border (no layout of footprints does); above ``by_side`` the longest chart's box is wider
    than that square. No scale above the smaller fits."""
    inner = resolution - 2 * padding
    total = sum(ch.area for ch in charts)
    longest = float(np.array([ch.extent for ch in charts]).max())
    by_area = inner / np.sqrt(total)
    by_side = max(inner - 2 * _MARGIN, 1e-9) / longest
    return float(by_area), float(by_side)


def _first_scale(
    charts: list[_Chart], resolution: int, padding: int, by_area: float, by_side: float
) -> float:
    """The scale search's first guess: `_FIRST_GUESS` of the area bound, or just under the side
    bound if that is smaller (a chart as long as the texture: the sheet of ``bench_atlas.py``
    ends at 0.996 of it, where 0.88 of the bound took the search six trials to get there); for
    `_MODEL_CHARTS` charts or more the scale ``s`` at which squares of side ``sqrt(area) s +
    padding + 1`` (one per chart) cover `_MODEL_FILL` of the area inside the border (the root
    of a quadratic in ``s``), if that is smaller."""
    first = min(_FIRST_GUESS * by_area, by_side * (1 - _UNDER_SIDE))
    if len(charts) < _MODEL_CHARTS:
        return first
    area = np.array([ch.area for ch in charts])
    grow = padding + 1
    a, b = float(area.sum()), 2.0 * grow * float(np.sqrt(area).sum())
    c = len(charts) * grow**2 - _MODEL_FILL * (resolution - 2 * padding) ** 2
    if c >= 0:  # the padding alone would fill it: leave it to the search
        return first
    return min(first, (-b + np.sqrt(b * b - 4 * a * c)) / (2 * a))


def _best_run(
    runs: list[tuple[_Placed | None, float, int | None]], resolution: int
) -> tuple[_Placed | None, float, int | None]:
    """Combine the placement rules' trials at one scale: (placed, fraction, need).

    The fitting layout that needs the least height wins (ties: the first rule); `need` is the
    least height any rule needed and `fraction` the most area any rule placed.
    """
    fitting = [r for r in runs if r[0] is not None and (r[2] is None or r[2] <= resolution)]
    placed = min(fitting, key=lambda r: -1 if r[2] is None else r[2])[0] if fitting else None
    needs = [r[2] for r in runs if r[2] is not None]
    return placed, max(r[1] for r in runs), min(needs) if needs else None


def _trial_setup(charts: list[_Chart], cfg: PackConfig, scale: float = np.inf) -> tuple:
    """What every trial of :func:`pack_charts` shares: the trial function, its placement
    rules, the charts' order (largest first; ties by the longer side, then by input order),
    the quarter turns and the charts' turned outlines (`_Angles`; `scale`: the largest a
    trial will use, in texels per unit length)."""
    turns, angles = (4, int(cfg.angle_steps)) if cfg.rotate else (1, 1)
    if cfg.method == "raster":
        trial, rules = _raster_trial, _RULE_ORDER
    else:
        trial, rules = _rect_trial, ("boxes",)
    areas = np.array([ch.area for ch in charts])
    longest = np.array([ch.extent for ch in charts]).max(axis=1)
    order = np.lexsort((np.arange(len(charts)), -longest, -areas))
    oriented = _Angles(charts, angles, scale) if cfg.method == "raster" else None
    return trial, rules, order, turns, oriented


#: ``resolution = 0``: the first texture tried holds the charts' area at this utilization (the
#: raster packer's utilization on the test meshes is 0.6-0.8); a texture that is too small
#: grows to the height the trial needed (or by :data:`_GROW` when it cannot tell).
_FIRST_UTILIZATION = 0.8
_GROW = 1.05


#: ``max_chart_size`` at the density the search found: if the limited charts do not fit at it
#: (the placement rules are greedy, not monotone), it is lowered by this factor, a few times.
_DERIVED_SHRINK = 0.98
_DERIVED_TRIES = 8


def _limited(
    uvs: Sequence[np.ndarray],
    faces: Sequence[np.ndarray],
    areas3d: np.ndarray,
    s: float,
    max_chart_size: int,
) -> list[_Chart] | None:
    """The charts with those spanning more than ``max_chart_size`` texels at ``s`` texels per
    unit scaled down to that (their area weight times the factor squared), or None when no
    chart is above the limit (or there is none)."""
    if max_chart_size <= 0:
        return None
    charts = _prepare(uvs, faces, areas3d)
    longest = np.array([float(ch.extent.max()) for ch in charts])
    shrink = np.minimum(1.0, max_chart_size / (longest * s))
    if not (shrink < 1).any():
        return None
    return _prepare(uvs, faces, areas3d * shrink**2)


def _one_trial(charts: list[_Chart], s: float, G: int, p: int, cfg: PackConfig) -> _Placed | None:
    """The placement rules once at scale ``s`` on a ``G`` texture: the layout, or None."""
    trial, rules, order, turns, oriented = _trial_setup(charts, cfg, s)
    if max(float(ch.extent.max()) for ch in charts) * s + 2 * _MARGIN > G - 2 * p:
        return None  # the longest chart alone is wider than the texture
    runs = [trial(charts, order, s, G, p, turns, rule, oriented) for rule in rules]
    return _best_run(runs, G)[0]


def _pack_at_density(
    uvs: Sequence[np.ndarray], faces: Sequence[np.ndarray], areas3d: ArrayLike, cfg: PackConfig
) -> PackResult:
    """:func:`pack_charts` at one texel density (``cfg.texels_per_unit``, or the one the
    search finds) with the charts above ``cfg.max_chart_size`` texels scaled down: one trial
    of the placement rules at that scale, no search on the scale."""
    areas3d = np.asarray(areas3d, dtype=np.float64)
    p = int(cfg.padding)
    s = float(cfg.texels_per_unit)
    unlimited = None
    if s == 0:  # the density of the search, before the limit
        unlimited = pack_charts(uvs, faces, areas3d, config=replace(cfg, max_chart_size=0))
        s = unlimited.texels_per_unit
    charts = _limited(uvs, faces, areas3d, s, cfg.max_chart_size)
    if unlimited is not None and charts is None:
        return unlimited  # no chart above the limit: the search's own layout
    if charts is None:
        charts = _prepare(uvs, faces, areas3d)
    if cfg.resolution > 0:
        G = int(cfg.resolution)
        tries = 1 if unlimited is None else _DERIVED_TRIES
        for k in range(tries):
            if k:  # the found density: a little less, the limit applied again
                s *= _DERIVED_SHRINK
                charts = _limited(uvs, faces, areas3d, s, cfg.max_chart_size) or _prepare(
                    uvs, faces, areas3d
                )
            placed = _one_trial(charts, s, G, p, cfg)
            if placed is not None:
                return _finish(charts, placed, s, G, p, k + 1, cfg)
        raise SolverError(
            f"{len(charts)} charts do not fit a {G}x{G} texture with padding {p} at "
            f"{s:.6g} texels per unit length; lower the texel density or raise the resolution"
        )
    trial, rules, order, turns, oriented = _trial_setup(charts, cfg, s)
    extent = max(float(ch.extent.max()) for ch in charts) * s
    area = sum(ch.area for ch in charts) * s * s
    G = int(np.ceil(max(np.sqrt(area / _FIRST_UTILIZATION), extent + 2 * _MARGIN + 1))) + 2 * p
    n_trials = 0
    while G <= MAX_RESOLUTION:
        n_trials += 1
        placed, _, need = _best_run(
            [trial(charts, order, s, G, p, turns, r, oriented) for r in rules], G
        )
        if placed is not None:
            return _finish(charts, placed, s, G, p, n_trials, cfg)
        grown = int(np.ceil(G * _GROW))
        if need is not None:  # a square as tall as the trial needed, in area
            grown = max(grown, int(np.ceil(np.sqrt((G - 2 * p) * (need - 2 * p)))) + 2 * p)
        G = grown if G == MAX_RESOLUTION else min(grown, MAX_RESOLUTION)
    raise SolverError(
        f"{len(charts)} charts need more than a {MAX_RESOLUTION}x{MAX_RESOLUTION} texture at "
        f"{s:.6g} texels per unit length (padding {p}); lower the texel density"
    )


def pack_charts(
    uvs: Sequence[np.ndarray],
    faces: Sequence[np.ndarray],
    areas3d: ArrayLike,
    *,
    config: PackConfig | None = None,
) -> PackResult:
    """Scale, rotate and pack charts into the unit square.

    Parameters
    ----------
    uvs : sequence of (n_i, 2) float ndarray
        Per chart, a bijective planar map at any position, scale and rotation.
    faces : sequence of (m_i, 3) int ndarray
        Per chart, triangles indexing its `uvs` rows.
    areas3d : (n_charts,) float array_like
        Per chart, the 3-D surface area; every chart's packed uv area is proportional to it.
    config : PackConfig, optional
        Options; defaults to ``PackConfig()``.

    Returns
    -------
    PackResult
        Packed coordinates, the per-chart affine maps, the global scale and the utilization.

    Raises
    ------
    InvalidMeshError
        If the list is empty, shapes or indices are wrong, a chart has zero (or non-finite)
        3-D area, or a chart's uv map spans no area.
    SolverError
        If no scale lets the charts fit (more charts than the texture has room for at this
        resolution and padding).

    Notes
    -----
    Charts' footprints (texels touched by their closed triangles) at `resolution` end up at
    Chebyshev distance greater than `padding` from each other, i.e. with at least `padding`
    empty texels in between, and no footprint texel lies within `padding` texels of the border.
    The layout is deterministic.
    """
    cfg = PackConfig() if config is None else config
    if cfg.texels_per_unit > 0 or cfg.max_chart_size > 0:
        return _pack_at_density(uvs, faces, areas3d, cfg)
    charts = _prepare(uvs, faces, areas3d)
    G, p = int(cfg.resolution), int(cfg.padding)
    # Safeguarded secant search on the scale: `lo` is the largest scale that fitted so far, no
    # scale above `hi` fits. Every trial runs the placement rules side by side (one thread each:
    # the compiled trials release the GIL); its outcome narrows the bracket and predicts the next
    # scale, until the stop rule holds.
    by_area, by_side = _scale_bounds(charts, G, p)
    hi = min(by_area, by_side)
    setup = _trial_setup(charts, cfg, hi)
    rules = setup[1]
    lo, best = 0.0, None
    s = _first_scale(charts, G, p, by_area, by_side)
    n_trials = 0
    with ThreadPoolExecutor(max_workers=min(len(rules), os.cpu_count() or 1)) as pool:
        for n_trials in range(1, _MAX_SHRINK + 1):
            placed, fraction, need = _trial_at_scale(pool, setup, charts, s, G, p, n_trials)
            fits = placed is not None
            if fits:
                lo, best = s, placed
            else:
                hi = s
            fills = fits and _fills_the_texture(need, G, p)
            full = fills and len(charts) >= _SMOOTH_CHARTS
            if best is not None and _search_done(lo, hi, n_trials, full):
                break
            s = _next_scale(s, lo, hi, fits, fraction, need, G, p, len(charts) >= _MODEL_CHARTS)
            if fills:
                s = min(s, lo * (1 + _FULL_STEP))
    if best is None:
        raise SolverError(
            f"{len(charts)} charts do not fit a {G}x{G} texture with padding {p} at any scale "
            f"down to {s:.3g} texels per unit length"
        )
    return _finish(charts, best, lo, G, p, n_trials, cfg)


# ----------------------------------------------------------------------------------------------
# the steps of the scale search


def _trial_at_scale(
    pool: ThreadPoolExecutor, setup: tuple, charts: list[_Chart], s: float, G: int, p: int, k: int
) -> tuple[_Placed | None, float, int | None]:
    """Trial `k` of the search: every placement rule of `setup` (:func:`_trial_setup`) at scale
    `s`, side by side on `pool`, combined by :func:`_best_run` into (placed, fraction, need)."""
    trial, rules, order, turns, oriented = setup
    runs = list(pool.map(lambda rule: trial(charts, order, s, G, p, turns, rule, oriented), rules))
    logger.debug("pack trial %d: scale %.6g needs %s", k, s, [r[2] for r in runs])
    return _best_run(runs, G)


def _fills_the_texture(need: int | None, G: int, p: int) -> bool:
    """Whether a fitting layout's height uses all but `_FULL` of the texture's side inside the
    border (the "full" stop, for `_SMOOTH_CHARTS` charts or more)."""
    return need is not None and need - 2 * p >= (G - 2 * p) * (1 - _FULL)


def _search_done(lo: float, hi: float, n_trials: int, full: bool) -> bool:
    """The stop rule, once some layout fitted (``lo > 0``): the bracket is within `_SCALE_TOL`,
    or `_MAX_TRIALS` trials ran, or the last fit fills the texture."""
    return hi / lo <= 1 + _SCALE_TOL or n_trials >= _MAX_TRIALS or full


def _predicted_scale(
    s: float, fits: bool, fraction: float, need: int | None, G: int, p: int
) -> float | None:
    """The secant step: the scale the trial at `s` predicts, or None when it predicts nothing.

    A trial that reports the height it needed (``need``, on its taller canvas) predicts the
    scale at which its layout would fill the texture's side: the area a layout covers grows
    with the scale's square, so ``s * sqrt(inner side / inner height needed)``. A rectangle
    trial that failed reports only the fraction of the area it placed: ``s * sqrt(fraction)``,
    kept within [`_SHRINK_MOST`, `_SHRINK_LEAST`] times s. A rectangle trial that fitted
    reports nothing (the caller bisects).
    """
    if not fits and need is None:
        return s * float(np.clip(np.sqrt(fraction), _SHRINK_MOST, _SHRINK_LEAST))
    if need is not None:
        return s * float(np.sqrt((G - 2 * p) / max(need - 2 * p, 1)))
    return None


def _next_scale(
    s: float,
    lo: float,
    hi: float,
    fits: bool,
    fraction: float,
    need: int | None,
    G: int,
    p: int,
    many: bool = False,
) -> float:
    """The next scale to try: the secant prediction (:func:`_predicted_scale`), safeguarded.

    Once a layout fitted (``lo > 0``) a prediction outside the bracket's interior (half of
    `_SCALE_TOL` in from either end), or none, is replaced by bisection, ``sqrt(lo * hi)``.
    Before that, the prediction stays at least ``1 - _UNDER_FAILED`` under `hi`, the last scale
    that failed; with `many` charts, or after a near miss (a raster trial that needed at most
    `_NEAR_MISS` more of the side than there is), a failed raster trial's prediction is aimed
    at `_AIM` of the texture's side instead, and stays just under `hi` (half of `_SCALE_TOL`).
    """
    margin = 1 + _SCALE_TOL / 2
    guess = _predicted_scale(s, fits, fraction, need, G, p)
    near = need is not None and need - 2 * p <= (1 + _NEAR_MISS) * (G - 2 * p)
    if lo > 0:
        if guess is None or not lo * margin <= guess <= hi / margin:
            guess = np.sqrt(lo * hi)
    elif (many or near) and need is not None:
        guess = min(s * float(np.sqrt(_AIM * (G - 2 * p) / max(need - 2 * p, 1))), hi / margin)
    else:
        guess = min(guess, _UNDER_FAILED * hi)
    return float(guess)


def _finish(
    charts: list[_Chart],
    placed: _Placed,
    s: float,
    G: int,
    p: int,
    n_trials: int,
    cfg: PackConfig,
) -> PackResult:
    to_tex, row, col = placed
    M = to_tex @ np.stack([ch.to_q for ch in charts])
    M[:, :2, 2] += np.column_stack([col, row])
    texel = M[:, :2].copy()  # chart uv -> texels
    M[:, :2] /= G
    transforms = np.empty((len(charts), 2, 3))
    transforms[[ch.index for ch in charts]] = M[:, :2]
    # loop over charts: one small product each (the same arithmetic, bit for bit, as ever)
    out_uvs = [ch.uv @ m[:2, :2].T + m[:2, 2] for ch, m in zip(charts, M, strict=True)]
    U = np.concatenate(out_uvs)
    width, height = _trimmed(U.max(axis=0) * G, G, p) if cfg.trim else (G, G)
    if (width, height) != (G, G):  # the same layout, u over the width and v over the height
        M[:, :2] = texel / np.array([width, height], dtype=np.float64)[None, :, None]
        transforms[[ch.index for ch in charts]] = M[:, :2]
        out_uvs = [ch.uv @ m[:2, :2].T + m[:2, 2] for ch, m in zip(charts, M, strict=True)]
        U = np.concatenate(out_uvs)
    nv = np.array([len(ch.uv) for ch in charts])
    offset = np.repeat(np.r_[0, np.cumsum(nv)[:-1]], [len(ch.F) for ch in charts])
    faces = np.concatenate([ch.F for ch in charts]) + offset[:, None]
    area = float(np.abs(signed_areas(U, faces)).sum())
    logger.info(
        "packed %d charts (%s) at %dx%d, padding %d: utilization %.4f after %d trials",
        len(charts),
        cfg.method,
        width,
        height,
        p,
        area,
        n_trials,
    )
    return PackResult(
        uvs=tuple(out_uvs),
        scale=s / width,
        transforms=transforms,
        utilization=area,
        resolution=G,
        padding=p,
        width=width,
        height=height,
    )


#: ``PackConfig.trim``: a side of the texture is cut to what the layout uses only where at least
#: this share of it would be empty. Most layouts fill their square (the scale search grows them
#: until the next trial no longer fits: the 17 meshes of ``bench_atlas.py --quick`` leave 0-3% of
#: the height empty), so they keep the size the user asked for; a layout bound by one long chart
#: (the 3k sheet 44%, the capped cylinder 20% of the height) gets a rectangle that it fills.
TRIM_LEAST = 0.125
#: A trimmed side is rounded up to a multiple of this many texels: GPU texture compression works
#: on 4 x 4 blocks (BCn, ETC2, ASTC 4x4), and a side that is not a multiple of 4 cannot take it.
TRIM_MULTIPLE = 4


def _trimmed(top: np.ndarray, G: int, p: int) -> tuple[int, int]:
    """The texture's (width, height) for a layout on a ``G`` square whose footprints reach
    ``top`` (the largest x and y of its charts, in texels): each side is the last texel a
    footprint touches, plus 1, plus the padding, rounded up to `TRIM_MULTIPLE`, where that
    leaves at least `TRIM_LEAST` of `G` empty; `G` otherwise.

    A closed triangle touches texel row ``floor(y)`` at its top ``y`` (and row ``y`` itself when
    ``y`` is an integer), so ``floor(y) + 1 + p`` rows keep the padding to the new border; the
    tolerance covers the rounding of the affine maps' products.
    """
    need = np.floor(np.asarray(top) + 1e-6).astype(np.int64) + 1 + p
    side = -(-need // TRIM_MULTIPLE) * TRIM_MULTIPLE
    cut = side <= G * (1 - TRIM_LEAST)
    return int(side[0]) if cut[0] else G, int(side[1]) if cut[1] else G
