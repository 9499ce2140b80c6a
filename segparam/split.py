"""Parameterize every chart; split the charts that fail and try again.

Each chart goes to the Hessian solver (:func:`segparam.parameterize.parameterize_chart`). A chart
whose map is not bijective, or misses the distortion target, is bisected along the Fiedler vector of
its face graph (with the segmentation's crease-aware affinities, so cuts prefer high curvature;
from ``STRAIGHTEN_MIN_FACES`` faces the cut is straightened as the segmentation's borders are) and
both halves are solved again, recursively, up to a depth limit. Pieces too small for the solver,
and pieces past the depth limit, are projected onto their best-fit plane, and that projection is
kept only if it is bijective; otherwise they are bisected further. A single triangle always
projects bijectively, so the recursion ends and every chart that leaves this stage is bijective.

A planar chart (the face of a CAD part) skips the solver: its projection onto its plane is the
exact isometry the solver would return up to a rigid motion (method ``"planar"``). On the CAD
plate of ``benchmarks/bench_atlas.py`` (28 planar charts) the stage takes 0.8 s instead of 1.6 s.

A tube (every boundary loop turning by less than pi: the wall of a drilled hole, a pipe, a cone's
side, whose map as it is would fold, ``TUBE_TURNING``) with two loops is cut open along the
shortest edge path from one loop to the other and solved as the disk it then is
(:func:`_opened`): a developable tube becomes one chart with one cut that unrolls without
stretch, where a bisection gives two charts and two cuts. The chart keeps both copies of the
cut's vertices (``Chart.vertices`` repeats them). If that map fails too, or the tube has more
loops, it is bisected as any chart.

Curvature decides two shortcuts. A cap, a disk holding more curvature of one sign than any map
within the stretch target allows (the halves of small spheres, ``CAP_CURVATURE``), or more
positive curvature inside whatever saddles it holds besides (a bone's knob, ``CAP_NET``), or a
disk whose least-distorting conformal flattening stretches far past the target (a folded piece
of a coarse brain, ``CONFORMAL_STRETCH_CUT``), is bisected without being solved first
(:func:`_caps`). A knob-like piece that fails again after a
bisection is first cut along a slit from its innermost vertex to its rim and solved once more
(:func:`_slit_charts`, ``SLIT_MIN_CURVATURE``): the slit's tip takes up curvature as a cone's
apex does, and the piece often maps as one chart where a bisection made two (the bone scan of
``benchmarks/bench_atlas.py``: 20 -> 13 charts).

Once every chart meets the targets, a small chart whose distortion sits at one spot (a cone of a
coarse scan) is bisected again when that removes most of it (:func:`_split_for_gain`,
``min_split_gain``): on the realistic 2k-face brain of ``benchmarks/bench_atlas.py`` 98 -> 111
charts and angle distortion 1.0845 -> 1.0714 (at the other defaults). Last, a small chart
still above ``slit_above`` in angle distortion whose strongest cone sits by its rim is cut along
the slit from that cone to the rim and solved again (:func:`_slit_cones`): the boundary's
turning takes up the cone's defect, and no chart is added.

Small charts are mapped in bulk, not one Python round trip each (:func:`_bulk_charts`): every
chart that is projected on its first try (fewer than ``min_faces`` faces, or planar) is
projected and checked in one vectorized pass over all of them, and every small chart the solver
takes (at most ``BATCH_MAX_VERTICES`` vertices: the halves of small closed parts) is solved with
the others as one block-diagonal problem (:func:`segparam.parameterize.solve_charts`). Both give
the charts the per-chart path gives (the solver's up to a rigid motion and rounding); only a
chart that fails there goes on to the per-chart path and its splits. 2,000 one-triangle charts
took 2.6 s, 600 hemispheres of 300 small spheres 6.2 s. A large batch is cut by whole charts and
its parts solved side by side in this process and in helpers forked from it
(:func:`_solve_batch`, :class:`segparam.cores.Helpers`), with the one call's result; so are the
pieces the solver takes one by one in a round (:func:`_try_pieces`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import logging
import os
import signal
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .cores import Helpers, limit_blas, may_start_processes, stop_pool
from .errors import InvalidMeshError, check_choice, check_int, check_number
from .linalg import DENSE_LIMIT, spd_solver
from .mesh import (
    annulus_cut,
    boundary_edges,
    boundary_pieces,
    check_mesh,
    cone_slits,
    corner_angles,
    cotan_laplacian,
    curvature_shares,
    cut_along,
    disk_labels,
    edges,
    face_areas,
    face_normals,
    group_by_label,
    inner_curvature,
    interior_defect,
    interior_vertices,
    is_disk,
    label_topology,
    mesh_arrays,
    plane_basis,
    slit_cut,
    submesh,
    unit_frame,
)
from .parameterize import (
    METHODS,
    MIN_POINTS,
    REFINES,
    TANGENTS,
    ChartMaps,
    charts_quality,
    kernels_loaded,
    parameterize_chart,
    quality_records,
    solve_charts,
)
from .quality import ChartQuality, chart_quality
from .refine import ANGLE_WEIGHT, SMALL_CHART_FACES, slim_refine
from .segment import divide, divide_many, face_affinity
from .unfold import EDGE_TOL, developable, unroll_charts

log = logging.getLogger(__name__)

__all__ = ["Chart", "ChartSet", "SplitConfig", "parameterize_charts", "project_chart"]


#: Default L2-stretch target (``SplitConfig.max_stretch``). Measured with
#: ``benchmarks/bench_quality.py`` (refine "slim", angle weight 16): at 1.02 brain-20k keeps its
#: 8 charts (L2 1.0083), fsaverage5's cortex goes 57 -> 68 charts (L2 1.0143 -> 1.0092), the
#: icosphere 2 -> 4 (1.061 -> 1.006); 1.01 costs fsaverage5 106 charts and 2-4x the stage time.
MAX_STRETCH = 1.02
#: Charts with fewer faces are not split for stretch below ``SMALL_CHART_MAX_STRETCH``: at the
#: default ``min_faces`` (8) these are the pieces the split stage projects onto their plane (and
#: refines, :func:`_refine_projections`). It was 64, which kept the 40-face halves of small
#: spheres at L2 1.026 (angle 1.244): a split per piece cost a solver call each then (300 spheres:
#: 1.5 -> 60+ s); the pieces are solved in batches now (:func:`_solve_in_rounds`).
STRETCH_MIN_FACES = SMALL_CHART_FACES
#: ... unless their stretch is past this ceiling: a small chart this stretched is a bad map, not
#: a piece that a split would flatten little (the realistic 20k-face brain had a 7-face piece
#: whose projection was bijective at L2 3.6, Linf 12; the refinement overlapped it: it is split).
SMALL_CHART_MAX_STRETCH = 1.25
#: A chart that holds this much Gaussian curvature of one sign (radians: its faces'
#: :func:`segparam.mesh.curvature_shares`) is a cap no map meets ``max_stretch`` <=
#: ``MAX_STRETCH`` on: it is cut before any solve (:func:`_caps`). On spherical caps the solver's
#: L2 reaches 1.02 at 4.05-4.1 rad (icospheres subdivided 3-5 times: 4.13 rad 1.0207, 3.93 rad
#: 1.0181) and 1.027 at 4.5. Of 3,278 pieces the split stage solved on 27 meshes (the quick
#: set, the turned CAD parts, capsules, spheres, three realistic brains), the 626 caught by
#: these three bounds all failed (600 of them the halves of the 300 jittered spheres, whose round
#: took 0.24 s of their 0.64 s stage); the pieces that passed with 4.5 rad or more were
#: CAD walls whose curvature sits on their rims (a cylinder's, a cone's side), or noisy.
CAP_CURVATURE = 4.5
#: ... of which at least this much inside the chart, at its inner vertices (Gauss-Bonnet: what
#: the boundary's turning cannot take up; a cylinder's side or a cone's holds none, its
#: curvature is on the rim; the jittered spheres' halves hold 3.3-5 rad) ...
CAP_INNER = 3.25
#: ... and of one sign: the inner defects' sum at least this share of their absolute sum (a
#: noisy scan's or a bunny's piece of 4-5 rad with saddles in it mapped within the targets).
CAP_ONE_SIGN = 0.9
#: A disk whose inner vertices' angle defects sum to at least this much (radians) misses the
#: target whatever saddles it holds besides, and is cut before any solve too: its positive
#: curvature alone is at least that, what a cap that misses it holds. Of the 4,012 pieces the
#: split stage solved on 31 meshes (the quick set of ``bench_atlas.py``, the bunny, the range
#: scan, the turned parts, ``data/brain.obj``, realistic brains of 2k-8k faces at several
#: seeds), all 47 of 4.5 rad or more failed (the bone's three knobs, 6.8-7.3 rad, at L2 1.14;
#: the cow's pieces of 84-89 faces, 7.3-8.3 rad), the most that passed held 4.23 (L2 1.011);
#: cutting them at once gave the same atlases on 37 meshes and 0.92x the time on the bone,
#: 0.91x on the bunny (BENCHMARKS.md 0.1, session 24). Not its negative: saddle-shaped pieces
#: of -4 to -6.3 rad mapped within the target (8 of 27; the range scan's -6.25 rad piece at L2
#: 1.002).
CAP_NET = 4.5
#: A disk whose conformal flattening of least area distortion (:func:`_conformal_stretch`)
#: stretches at least this much (Sander's L2) misses the target too, and is cut before any
#: solve: the solver's refined maps lean conformal (``angle_weight``), and they stretch less
#: than that flattening by a margin, never past it. Of the 4,602 pieces the split stage solved on
#: 28 meshes (the quick set of ``bench_atlas.py``, the bunny, the range scan, the turned parts,
#: ``data/brain.obj``, realistic brains of 2k-8k faces at several seeds) the most stretched
#: flattening of a piece that met the target was at 1.051 (the bunny with holes', mapped at
#: 1.0184); from 1.06 up all 481 missed it (66% of the faces solved in vain), from 1.08 all 379
#: (53%). At 1.08 the margin over 1.051 is half the excess again. BENCHMARKS.md 0.1, session 24.
CONFORMAL_STRETCH_CUT = 1.08
#: A piece that fails again after a bisection (at this depth or deeper) and holds at least
#: ``SLIT_MIN_CURVATURE`` radians at its inner vertices is first cut open along a slit
#: (:func:`_slit_open`): the shortest edge path from its innermost vertex to its boundary, which
#: gives the boundary room to turn where a cap's curvature would otherwise be spread as stretch
#: (the tip of a slit takes up curvature as a cone's apex does). The bone scan of
#: ``bench_atlas.py``: its three knobs' halves (2.9-3.0 rad of curvature each) mapped at L2
#: 1.020-1.024, over the target, and were each cut in two again; with a slit they map at
#: 1.0065-1.0085 (angle 1.038-1.043): 20 -> 13 charts (xatlas: 18), L2 1.0048 -> 1.0063, angle
#: 1.030 -> 1.033, seams 9.9 -> 8.4, utilization 0.673 -> 0.658. Segmentation charts (depth 0)
#: are not slit: the spheres' and capsules' halves would become one chart each where two
#: quarters map with half the stretch (300 spheres: L2 1.004 -> 1.011, angle 1.087 -> 1.125).
SLIT_MIN_DEPTH = 1
#: ... the inner curvature (radians) a piece needs for a slit: knob-like pieces. At 1.0 the
#: realistic brains' folded pieces took slits too (a 2k brain 106 -> 85 charts, angle 1.084 ->
#: 1.100); at 2.5 the brains of ``bench_atlas.py``'s quick set and data/brain.obj keep their
#: atlases (a realistic 2k brain 106 -> 92 charts, angle 1.084 -> 1.093).
SLIT_MIN_CURVATURE = 2.5
#: ... and the share of that curvature that must be of one sign (the inner defects' sum over
#: their absolute sum): a knob, not a folded piece whose saddles a slit cannot relieve. Of 69
#: slits tried on ten meshes (the quick set's brains and real meshes, three realistic brains),
#: 6 of the 32 below 0.6 mapped within the targets, 24 of the 37 above (the bone's six at
#: 0.62-0.73, the airplane's two at 0.65 and 0.90); each failed try costs a solve.
SLIT_ONE_SIGN = 0.6
#: Default ``SplitConfig.min_split_gain``: after the targets are met, a small chart is bisected
#: once more (:func:`_split_for_gain`) when that lowers the atlas's distortion excess (atlas
#: ``L2^2 - 1`` plus angle ``- 1``, :func:`_excess`) by at least this much per chart added, and
#: by at least ``GAIN_MIN_SHARE`` of the chart's own excess. Measured (``parameterize_charts`` on
#: the segmentation of ``bench_atlas.py``'s meshes, seed 0; charts / L2 / angle): the realistic
#: 2k brain 100 / 1.0076 / 1.0820 -> 117 / 1.0062 / 1.0659 (xatlas: 134 / 1.0207 / 1.0573; the
#: goal, xatlas + 0.02 = 1.0773, was missed), brain-20k 101 / 1.0072 / 1.0443 -> 102 / 1.0070 /
#: 1.0436; fsaverage5, the wavy scan, the icosphere, the torus, the plate, the sheets and the 300
#: spheres unchanged. 1e-3: the brain 105 / 1.0069 / 1.0749; 5e-4: 122 / 1.0061 / 1.0634.
MIN_SPLIT_GAIN = 7e-4
#: ... and the share of the chart's own excess that its bisection must remove: a chart whose
#: distortion sits at one spot (a cone of the coarse 2k brain, where a 17-face chart has angle
#: 1.19) loses most of it when cut there (the 2k brain's bisections kept removed 70-100%), while
#: a chart that is curved all over keeps most of it in both halves (the icosphere's quarters lose
#: 60% of it, the torus's 32-36%, the wavy scan's charts 1-16%): splitting those trades charts for
#: stretch everywhere at once, what ``max_stretch`` is for. Without it (and without the size
#: limit below), at a gain of 1e-3, the icosphere goes from 4 charts to 8 (xatlas makes 6).
#: 0.6: the 2k brain 119 charts / angle 1.0637, brain-20k 103; 0.8: 115 / 1.0686, brain-20k 101.
GAIN_MIN_SHARE = 0.7
#: ... and the largest chart tried (a bound on the cost): without it no bisection of a chart
#: above 154 faces was kept on any mesh of ``bench_atlas.py --quick`` (the wavy scan's 66 charts
#: of 247-1079 faces removed 1-16% of their excess, the icosphere's and the torus's 5,000-face
#: quarters 60% and 32%), and trying them cost the stage 1.9 s of CPU on the wavy scan (1.4 ->
#: 3.3 s) and 0.5-0.8 s on the icosphere and the torus. 256 until session 25: of the 541
#: charts tried on 37 meshes (the quick set, realistic brains of 2k-8k faces at six seeds, the
#: bunny, the range scan, turned parts, data/brain.obj), the 65 bisections kept were of 5-49
#: faces and one of 148 (brain-20k); the 74 charts of more than 160 faces were all kept whole,
#: and trying them cost the cow 488 -> 415 ms a build, the bunny with holes 595 -> 556, the
#: bone 215 -> 203, data/brain.obj 1,104 -> 1,065 (the same atlases on the 37 meshes).
GAIN_MAX_FACES = 160
#: ... and the least excess of its own (``(L2^2 - 1) + (angle - 1)`` of the chart alone) a chart
#: needs to be tried: a chart this close to an isometry is left whole however large its share
#: of a small mesh (a 4-face strip folded down its middle, refined to L2 1.0000 / angle 1.0017,
#: was cut in two). The bisections kept on the 2k brain were of charts of 0.11-0.25, brain-20k's
#: one of 0.11.
GAIN_MIN_EXCESS = 0.02
#: Default ``SplitConfig.slit_above``: a finished chart whose angle distortion is above this
#: has its strongest cone freed by a slit (:func:`_slit_cones`). The coarse brains' small charts
#: hold cones of 0.5-2 rad at a vertex, which no flattening takes up without distortion; on the
#: boundary the rim's turning does. Measured (hashes script over 37 meshes, BENCHMARKS.md
#: section 0.1, session 26): the 2k brains of seeds 0-5 angle 1.0729-1.0975 -> 1.0568-1.0796,
#: L2 1.0066-1.0082 -> 1.0032-1.0064, the same charts; at 1.08 with one slit a chart the seed-1
#: brain ended at 1.0712, over its bound (xatlas + 0.02 = 1.0662).
SLIT_ABOVE = 1.06
#: A slit chart is kept when its own excess (``L2^2 - 1`` plus angle ``- 1``) is at most
#: ``1 - CONE_SLIT_GAIN`` of the chart's (0.2: the 5k brain of seed 2 at 1.0717, over its bound
#: of 1.0707; 0.1: 1.0699, seams +1%) ...
CONE_SLIT_GAIN = 0.1
#: ... and lowers the atlas's excess by at least this: brain-20k's few small charts gained
#: 0.0004 of angle distortion for 1.6 points of utilization (the packer's noise) without it.
CONE_SLIT_MIN_GAIN = 1e-4
#: The charts tried: of 8 (``STRETCH_MIN_FACES``) to this many faces (the brains' charts of 64+
#: faces kept 23 of 130 slits tried, at 20k faces solved), whose strongest cone holds at least
#: this much (radians; the jittered spheres' quarters, 0.3-0.4 rad, kept slits of 27-29% gain at
#: twice their build's time; the brains' below 0.4: 3 of 7) ...
CONE_SLIT_MAX_FACES = 64
CONE_MIN_DEFECT = 0.4
#: ... at most this many edges from the rim (of 92 longer slits tried, 4 were kept) ...
CONE_SLIT_MAX_EDGES = 2
#: ... and holding enough of the atlas's excess that removing this share of it would gain
#: ``CONE_SLIT_MIN_GAIN`` (the same atlases on the brains and the cow as with no such bound;
#: the jittered spheres' 420 tiny candidates are not cut and solved in vain) ...
CONE_SLIT_MOST = 0.5
#: ... up to this many slits a chart, one per round (2, in a first version: the seed-1 brain
#: 1.0668, over its bound).
CONE_SLIT_ROUNDS = 3
#: A piece of at least ``STRAIGHTEN_MIN_FACES`` faces that is bisected gets the border between
#: its halves straightened by ``STRAIGHTEN_PASSES`` passes of the segmentation's majority
#: filter (as its own borders, ``SegmentConfig.smoothing``): the Fiedler vector's median cuts
#: through a band of faces and leaves one-face teeth, which cost seam length and, in the packed
#: atlas, room. Smaller pieces keep the median cut: the filter moves a large share of their
#: faces and their maps distort more (a prototype on the 2k brain: straightening every cut took
#: its angle distortion 1.0716 -> 1.0908, past issue 14's bound of xatlas + 0.02 = 1.077; from
#: 150 faces 1.0750, from 200 1.0729). From 200 faces, on ten meshes at seeds 0-2 (bone, cow,
#: airplane, bunny with holes, fsaverage5, brain-20k, brain-2k, icosphere, torus, bunny;
#: remeshing off): seams 2.8% shorter on average (none longer), utilization +0.4 points on
#: average (20 sets up, 7 down, -1.8 to +2.2: the packer's noise around a small gain), L2
#: +0.0003 at most, angle distortion +0.0003 on average and +0.0015 at most (BENCHMARKS.md 0.1,
#: session 23).
STRAIGHTEN_MIN_FACES = 200
STRAIGHTEN_PASSES = 4
#: ``segment.divide``'s ``straighten`` argument.
_STRAIGHTEN = (STRAIGHTEN_MIN_FACES, STRAIGHTEN_PASSES)
#: A chart with two or more boundary loops, each turning by less than this in total (the sum
#: over its vertices of pi minus their corner angles, the discrete geodesic curvature), is a
#: tube: a drilled hole's wall or a pipe (a straight cylinder's loops turn by 0), a cone's side
#: (+-2 pi sin of its half-angle). A near-isometric map keeps that turning, and a bijective
#: planar image of an annulus turns its loops by +-2 pi (a flat washer), so a tube's map as it
#: is folds: it is not solved so but cut open into a disk if it has two loops
#: (:func:`_opened`), else split. Half a washer's turning separates the two: the CAD plate's 6
#: hole walls turn by 0.00 pi, cones' sides by +-0.33-0.60 pi; the brain pieces with holes
#: whose maps failed (brain-2k and realistic 2k brains of seeds 1-2) have an inner loop at -1.58
#: to -2.85 pi, and none of them, cut open, mapped within the targets either (pi / 4 until
#: session 13, when tubes were split instead; BENCHMARKS.md, section 0.1).
TUBE_TURNING = np.pi
#: A tube whose loops are on average longer than this many times the cut between them is not
#: opened but split: as one strip it would bind the texture's side wherever it is the longest
#: chart. A bushing's walls (loops 3.1 and 6.3 around, 0.3 apart) opened into strips of 10:1 and
#: 21:1 took its atlas's utilization from 0.556 to 0.189; a plain cylinder (2.1:1), cones' sides
#: (1.3:1), the CAD plate's hole walls (3.8:1) and a pipe (3.1:1) open.
TUBE_MAX_ASPECT = 6.0
#: Meshes from this many faces up send whole charts to spawned workers; smaller ones are
#: parameterized here, sharing their large batches with forked helpers from
#: ``HELPERS_MIN_FACES`` (``_solve_batch``): starting a spawned worker costs about a second.
PARALLEL_MIN_FACES = 100_000
#: Meshes from this many faces up (and under ``PARALLEL_MIN_FACES``) share their large solver
#: batches with forked helpers; smaller ones are parameterized in this process alone. A fork
#: costs 30-60 ms here (the fork, the helper's start, the copy-on-write faults that slow this
#: process afterwards) and two processes each take about 70% of the whole's time, so helpers
#: repay that only over a stage with enough work to share. Builds with helpers / without (min
#: of 3, remeshing off, session 25): the cow (5.8k faces) 552 / 499 ms, the bunny with holes
#: (10k) 613 / 585, the airplane (10.8k) 535 / 474, brain-like surfaces of 8k 690-700 /
#: 690-712, 12k 858 / 908, 15k 932 / 989, brain-20k 1,008 / 1,079, fsaverage5 840 / 925.
HELPERS_MIN_FACES = 12_000
#: A chart is planar when no unit face normal differs from the first by more than this.
PLANAR_TOL = 1e-9
#: Charts of at most this many vertices that need the solver are solved together, as one
#: block-diagonal problem (see :func:`_bulk_charts`). Alone, a small chart costs 10-15 ms, mostly
#: Python and library-call overhead (6.2 s for the 600 hemispheres of 300 small spheres); in a
#: batch the dense eigenproblem is the cost, and it grows like the cube of the size. Measured per
#: spherical cap, one BLAS thread, batches of 40: 36 vertices 1.0 ms (alone 10.9), 81: 2.3
#: (14.3), 144: 3.8 (11.7), 256: 10.1 (15.6, 6.3 of it the batched ``eigh``). Up to the dense
#: solver's limit (400, where a chart alone is dense too): the realistic 20k brain's stage (93
#: charts, many split pieces of 250-400 vertices) 1.53-1.89 -> 1.31-1.34 s of CPU, fsaverage5
#: 0.86-0.94 -> 0.79-0.80, the same charts (``parameterize_charts`` timed 3 times each).
BATCH_MAX_VERTICES = DENSE_LIMIT


@dataclass(frozen=True)
class SplitConfig:
    """Options of :func:`parameterize_charts`.

    Attributes
    ----------
    method : {"hessian", "classic-hlle"}
    tangent : {"normals", "pca"}
        Passed to the solver.
    max_depth : int
        Most bisections (>= 0) of one segmentation chart before the planar fallback takes over.
    max_distortion : float or None
        Angle-distortion target (finite, >= 1): a bijective chart above it is split too (None:
        no target).
    max_stretch : float or None
        L2-stretch target (Sander's, finite, >= 1): a bijective chart of at least
        ``STRETCH_MIN_FACES`` faces above it is split too (None: no target). The knob that
        trades charts against stretch (``benchmarks/bench_quality.py`` draws the curve).
    min_split_gain : float or None
        After the targets: a chart of at most ``GAIN_MAX_FACES`` faces is bisected once more
        when that lowers the atlas's distortion excess (``L2^2 - 1`` plus angle ``- 1``, area
        weighted) by at least this much (finite, >= 0) per chart added and by at least
        ``GAIN_MIN_SHARE`` of the chart's own excess (None: no such splits).
    min_faces : int
        Pieces with fewer faces (>= 1) skip the solver and use the planar projection.
    n_jobs : int
        Processes that share the work (0: one per CPU, 1: this one alone): spawned workers for
        meshes of at least ``PARALLEL_MIN_FACES`` faces, below that (from
        ``HELPERS_MIN_FACES``) helpers forked for the large solver batches
        (:func:`_solve_batch`, Linux). Charts are independent, so the result does not depend
        on it.
    refine : {"slim", "arap", "none"}
        The refinement after the solver (see :func:`segparam.parameterize.parameterize_chart`):
        ``"none"`` keeps the paper's map.
    angle_weight : float
        ``refine="slim"``: weight (finite, >= 0) of the conformal term in the refined energy;
        higher trades L2 stretch for less angle distortion (:func:`segparam.refine.slim_refine`;
        charts under ``SMALL_CHART_ANGLE_FACES`` faces get ``SMALL_CHART_ANGLE_SCALE`` times it).
    slit_above : float or None
        Last: a solver's chart whose angle distortion is above this (finite, >= 1) is cut along a
        slit from its strongest cone to its rim and solved again, kept when that removes most
        of its distortion (:func:`_slit_cones`; no chart is added, the slit becomes a seam;
        None: no such slits).

    Raises
    ------
    ConfigError
        If a field has the wrong type (an integer where a number is asked is fine, a bool never
        is) or is out of range; the message names the field.
    """

    method: str = "hessian"
    tangent: str = "normals"
    max_depth: int = 6
    max_distortion: float | None = None
    max_stretch: float | None = MAX_STRETCH
    min_split_gain: float | None = MIN_SPLIT_GAIN
    min_faces: int = 8
    n_jobs: int = 0
    refine: str = "slim"
    angle_weight: float = ANGLE_WEIGHT
    slit_above: float | None = SLIT_ABOVE

    def __post_init__(self) -> None:
        # Every field, type first (bool is not a number here); numbers are stored as plain
        # int / float. Messages start with the key: config_from_dict adds the file and [split].
        checked = {
            "method": check_choice("method", self.method, METHODS),
            "tangent": check_choice("tangent", self.tangent, TANGENTS),
            "max_depth": check_int("max_depth", self.max_depth, low=0),
            "max_distortion": check_number(
                "max_distortion", self.max_distortion, low=1, optional=True
            ),
            "max_stretch": check_number("max_stretch", self.max_stretch, low=1, optional=True),
            "min_faces": check_int("min_faces", self.min_faces, low=1),
            "min_split_gain": check_number(
                "min_split_gain", self.min_split_gain, low=0, optional=True
            ),
            "n_jobs": check_int("n_jobs", self.n_jobs, low=0),
            "refine": check_choice("refine", self.refine, REFINES),
            "angle_weight": check_number("angle_weight", self.angle_weight, low=0),
            "slit_above": check_number("slit_above", self.slit_above, low=1, optional=True),
        }
        for name, value in checked.items():
            object.__setattr__(self, name, value)


@dataclass(frozen=True)
class Chart:
    """One bijectively mapped chart.

    Attributes
    ----------
    faces : (k,) int64 ndarray
        Indices into the mesh's ``F``.
    vertices : (n,) int64 ndarray
        Mesh vertex of each local vertex; ``F[faces]`` equals ``vertices[local_F]``. A mesh
        vertex can come twice: on the seam of a tube cut open into one chart, a copy for
        either side (the faces across the seam do not share it).
    local_F : (k, 3) int64 ndarray
        The chart's faces in local vertex indices.
    uv : (n, 2) float64 ndarray
        Near-isometric coordinates of the local vertices.
    quality : ChartQuality
    source : int
        The segmentation chart it came from.
    depth : int
        Bisections from the segmentation chart to this piece.
    method : str
        ``"hessian"`` / ``"classic-hlle"`` (the solver), ``"planar"`` (a planar chart, projected
        onto its plane: exact), ``"developable"`` (a developable one, unrolled: exact, see
        :mod:`segparam.unfold`) or ``"projection"`` (the fallback for small or failing pieces).
    """

    faces: np.ndarray
    vertices: np.ndarray
    local_F: np.ndarray
    uv: np.ndarray
    quality: ChartQuality
    source: int
    depth: int
    method: str


@dataclass(frozen=True)
class ChartSet:
    """The charts of a mesh after split and retry.

    Attributes
    ----------
    charts : tuple of Chart
        All bijective; together they hold every face exactly once.
    splits : (s,) int64 ndarray
        Number of bisections each segmentation chart needed (``len(pieces) - 1``).
    first_pass_bijective : (s,) bool ndarray
        Whether the solver mapped each segmentation chart bijectively on its first try (False
        for a chart cut without a try).
    cut_untried : (s,) bool ndarray or None
        The segmentation charts cut before any solve, because no map of them would meet the
        stretch target (:func:`_caps`); None where not recorded (stage files of earlier
        versions).
    """

    charts: tuple[Chart, ...]
    splits: np.ndarray
    first_pass_bijective: np.ndarray
    cut_untried: np.ndarray | None = None


def project_chart(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Orthogonal projection onto the least-squares plane, oriented to keep the winding.

    The normal is the area-weighted mean face normal (it faces the same way as the triangles), so
    a piece that is a height field over that plane maps without flips.

    Returns
    -------
    (n, 2) float64 ndarray
    """
    n = (face_normals(V, F) * face_areas(V, F)[:, None]).sum(axis=0)
    if np.linalg.norm(n) < 1e-300:
        n = np.linalg.svd(V - V.mean(axis=0), full_matrices=False)[2][-1]
    n = n / np.linalg.norm(n)
    (b1,), (b2,) = plane_basis(n[None])
    X = V - V.mean(axis=0)
    return np.stack([X @ b1, X @ b2], axis=1)


@contextlib.contextmanager
def _sigint_blocked():
    """Block SIGINT in this thread while worker processes start (POSIX; a no-op elsewhere).

    A process started meanwhile inherits the blocked mask; a Ctrl-C that arrives meanwhile is
    delivered here when the block ends.
    """
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _jobs(cfg: SplitConfig) -> int:
    """Worker processes the config asks for (``n_jobs``; 0: one per CPU), or 1 in a daemonic
    process (a ``multiprocessing`` pool's worker), which may not start any."""
    if not may_start_processes():
        return 1
    return cfg.n_jobs or os.cpu_count() or 1


def _warm_worker(blas_threads: int = 1) -> None:
    """A worker's start: its BLAS threads limited to ``blas_threads`` (the cores left per worker),
    then the solver imported and its compiled kernel loaded on a small bent grid, before the
    first chart arrives (about 1 s of imports and 0.3-0.9 s of kernel loading).

    Without the limit each worker's BLAS started a thread per core: on 2 cores, 2 workers ran 4
    busy threads, and the 1M-face brain's parameterize stage took 24.6-26.0 s against 18.0-18.3 s
    with one thread each (two runs each; BENCHMARKS.md section 0, session 9).
    """
    limit_blas(blas_threads)
    _solve_a_bent_grid()


def _solve_a_bent_grid() -> None:
    """Map a 5 x 5 bent grid: loads (or, on a first run, compiles) the solver's kernels."""
    u, v = np.meshgrid(np.linspace(0.0, 1.0, 5), np.linspace(0.0, 1.0, 5))
    V = np.stack([u.ravel(), v.ravel(), 0.3 * (u * v).ravel()], axis=1)
    q = (np.arange(4)[:, None] * 5 + np.arange(4)[None, :]).ravel()  # lower-left corners
    F = np.concatenate([np.stack([q, q + 1, q + 6], 1), np.stack([q, q + 6, q + 5], 1)])
    parameterize_chart(V, F, refine="slim")


def _before_the_helpers() -> None:
    """:class:`segparam.cores.Helpers`' ``prepare``: the solver's compiled kernels in this
    process before a helper is forked, so that the helpers do not each compile them again on a
    first run (the neighbourhood search, ~1 s)."""
    if not kernels_loaded():
        _solve_a_bent_grid()


def start_workers(config: SplitConfig | None = None):
    """Start the worker processes of :func:`parameterize_charts` ahead of it.

    Each worker's start-up (imports and the solver's compiled kernel, about 2 s of CPU) then
    overlaps with what the caller does meanwhile: :func:`segparam.pipeline.build_atlas` starts
    them before it cleans and segments a mesh of ``PARALLEL_MIN_FACES`` faces or more, on one
    core, and hands them over with ``parameterize_charts(..., workers=pool)``.

    Returns
    -------
    concurrent.futures.ProcessPoolExecutor or None
        None where the config asks for one job (or the machine has one CPU). The caller shuts
        it down (:func:`stop_workers`).
    """
    cfg = config or SplitConfig()
    jobs = _jobs(cfg)
    if jobs <= 1:
        return None
    pool = _new_pool(jobs)
    with _sigint_blocked():
        for _ in range(jobs):  # a submit starts a worker while none is idle
            pool.submit(int)
    return pool


def stop_workers(pool, *, now: bool = False) -> None:
    """Shut down the workers of :func:`start_workers` (None: nothing to do): after their tasks,
    or ``now``, cancelling what has not started (on an error or Ctrl-C)."""
    if pool is None:
        return
    if now:
        stop_pool(pool)
    else:
        pool.shutdown()


def _new_pool(jobs: int):
    """A pool of ``jobs`` spawned workers, each warmed up as it starts (:func:`_warm_worker`)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    ctx = multiprocessing.get_context("spawn")  # no fork after BLAS threads have started
    blas_threads = max(1, (os.cpu_count() or 1) // jobs)
    return ProcessPoolExecutor(
        max_workers=jobs, mp_context=ctx, initializer=_warm_worker, initargs=(blas_threads,)
    )


def parameterize_charts(
    V: np.ndarray,
    F: np.ndarray | None = None,
    labels: np.ndarray | None = None,
    *,
    config: SplitConfig | None = None,
    seed: int = 0,
    progress: Callable[[int], None] | None = None,
    affinity: sp.csr_matrix | None = None,
    workers=None,
    curvature: np.ndarray | None = None,
) -> ChartSet:
    """Map every chart of a segmentation bijectively, splitting the ones that fail.

    Small charts are mapped in bulk first (:func:`_bulk_charts`); the others, and the small ones
    that fail there, go one by one through the solver and its splits. Then the small charts whose
    bisection removes most of their distortion are bisected (``min_split_gain``,
    :func:`_split_for_gain`), and last the small charts still over ``slit_above`` are cut along
    a slit from their strongest cone to their rim when that removes enough of their distortion
    (:func:`_slit_cones`).

    Parameters
    ----------
    V : (n, 3) float ndarray
    F : (m, 3) int ndarray
    labels : (m,) int ndarray
        Chart of each face (see :func:`segparam.segment.segment`).
    config : SplitConfig, optional
    seed : int
    progress : callable, optional
        Called with the number of segmentation charts finished so far.
    affinity : (m, m) scipy.sparse.csr_matrix, optional
        The face affinity that failing charts are split on: the segmentation's
        (``Segmentation.affinity``), or by default :func:`segparam.segment.face_affinity` with
        its default weights, built on the first split.
    workers : concurrent.futures.ProcessPoolExecutor, optional
        Workers already started (:func:`start_workers`), used instead of starting new ones when
        the charts go to worker processes (``n_jobs``, ``PARALLEL_MIN_FACES``); the caller
        shuts them down.
    curvature : (m,) float ndarray, optional
        Each face's share of the Gaussian curvature (``Segmentation.face_curvature``), by which
        the caps that no map within ``max_stretch`` exists for are cut without a solve
        (:func:`_caps`); by default :func:`segparam.mesh.curvature_shares`, computed when a
        chart first may be one.

    Returns
    -------
    ChartSet
    """
    cfg = config or SplitConfig()
    V, F = check_mesh(*mesh_arrays(V, F))  # or a trimesh.Trimesh alone (labels by keyword)
    labels = np.asarray(-1 if labels is None else labels)
    if labels.shape != (len(F),) or labels.dtype.kind not in "iu" or labels.min() < 0:
        raise InvalidMeshError(
            f"labels must be {len(F)} non-negative integers (one chart per face), "
            f"got shape {labels.shape} and dtype {labels.dtype}"
        )
    labels = labels.astype(np.int64)
    if affinity is not None and affinity.shape != (len(F), len(F)):
        raise InvalidMeshError(
            f"affinity must be {len(F)} x {len(F)} (one row per face), got {affinity.shape}"
        )
    if curvature is not None and np.shape(curvature) != (len(F),):
        raise InvalidMeshError(
            f"curvature must be {len(F)} numbers (one per face), got shape {np.shape(curvature)}"
        )
    center, size = unit_frame(V)
    V = (V - center) / size  # scale-free; chart uvs are scaled back below
    n_src = int(labels.max()) + 1
    order, bounds = group_by_label(labels, n_src)
    sources = [order[bounds[s] : bounds[s + 1]] for s in range(n_src)]
    sub = _submeshes(F, labels, order, bounds)
    jobs = _jobs(cfg)
    affinity = _MeshAffinity(V, F, affinity)
    # From HELPERS_MIN_FACES to PARALLEL_MIN_FACES the large solver batches are shared with
    # forked helpers; above, whole charts go to the spawned workers (which then have the cores).
    with Helpers(
        jobs if HELPERS_MIN_FACES <= len(F) < PARALLEL_MIN_FACES else 1,
        prepare=_before_the_helpers,
    ) as helpers:
        # Small charts, all at once: already in mesh indices and units.
        bulk_rejected, bulk_bijective = np.zeros(n_src, dtype=bool), np.zeros(n_src, dtype=bool)
        cut_untried = np.zeros(n_src, dtype=bool)  # cut before any solve (_caps)
        shares = _curvature_source(V, F, curvature, cfg)
        final = _bulk_charts(
            V, F, sub, order, bounds, cfg, size, bulk_rejected, bulk_bijective, helpers=helpers,
            curvature=shares, capped=cut_untried,
        )  # fmt: skip
        if progress is not None and final:
            progress(len(final))
        in_bulk = np.zeros(n_src, dtype=bool)
        in_bulk[list(final)] = True
        rest = np.flatnonzero(~in_bulk).tolist()  # the charts that need the solver alone
        parallel = jobs > 1 and len(rest) > 1 and len(F) >= PARALLEL_MIN_FACES

        def task(src: int) -> tuple:
            """The arguments of :func:`_solve_source` for chart ``src`` (before ``cfg, seed``).

            A worker process cannot reach the mesh: it gets the chart's affinity at once.
            """
            faces = sources[src]
            vertices, local_F = sub.of(src)
            return V[vertices], local_F, affinity.of_chart(faces, now=parallel), src

        def shares_of(src: int) -> np.ndarray | None:
            """The curvature shares of chart ``src``'s faces (:func:`_solve_source`'s caps)."""
            return None if shares is None else shares()[sources[src]]

        results: dict[int, tuple[list[Chart], bool, bool]] = {}
        if parallel:
            from concurrent.futures import as_completed

            by_size = sorted(rest, key=lambda s: -len(sources[s]))  # big ones first
            pool = workers if workers is not None else _new_pool(min(jobs, len(rest)))
            try:
                # Ctrl-C goes to the whole process group. The workers start (and live) with SIGINT
                # blocked, a mask they inherit, so only this process sees it and stops them: no
                # traceback from a worker that was still importing.
                with _sigint_blocked():
                    futures = {
                        pool.submit(_solve_source, *task(s), cfg, seed, shares_of(s)): s
                        for s in by_size
                    }
                for done, future in enumerate(as_completed(futures), len(final) + 1):
                    results[futures[future]] = future.result()
                    if progress is not None:
                        progress(done)
            except BaseException:
                stop_pool(pool)
                raise
            if workers is None:
                pool.shutdown()
        else:
            results = _solve_in_rounds(
                V, F, rest, sources, sub, affinity, cfg, seed, size, bulk_rejected, bulk_bijective,
                progress, len(final), helpers, curvature=shares,
            )  # fmt: skip

        for src in rest:
            pieces, first, cut = results[src]
            final[src] = (_in_mesh(pieces, sources[src], sub.of(src)[0], size), first)
            cut_untried[src] |= cut
        charts: list[Chart] = []
        first_pass = np.zeros(n_src, dtype=bool)
        for src in range(n_src):
            pieces, first_pass[src] = final[src]
            charts.extend(pieces)
        if cfg.min_split_gain is not None:
            charts = _split_for_gain(V, F, charts, cfg, seed, size, affinity, helpers)
        charts = _slit_cones(V, F, charts, cfg, size, helpers)
        splits = np.bincount([c.source for c in charts], minlength=n_src) - 1
        return ChartSet(
            charts=tuple(charts), splits=splits, first_pass_bijective=first_pass,
            cut_untried=cut_untried,
        )  # fmt: skip


def _excess(charts: list[Chart], area: np.ndarray, *, own: bool = False) -> np.ndarray:
    """Each chart's part of the atlas's distortion excess: its share of the surface area times
    ``(L2^2 - 1) + (angle - 1)`` (0 for an isometry; that factor alone with ``own``). The
    atlas's own excess is the sum: its ``L2^2 - 1`` plus its angle distortion ``- 1`` (the figures
    of ``segparam.quality.distortion`` once every chart is scaled to its 3-D area, as the packer
    scales them)."""
    l2 = np.array([c.quality.l2_stretch for c in charts])
    angle = np.array([c.quality.angle_distortion for c in charts])
    if own:
        return (l2**2 - 1) + (angle - 1)
    share = np.array([area[c.faces].sum() for c in charts]) / area.sum()
    return share * ((l2**2 - 1) + (angle - 1))


def _split_for_gain(
    V: np.ndarray,
    F: np.ndarray,
    charts: list[Chart],
    cfg: SplitConfig,
    seed: int,
    size: float,
    affinity: _MeshAffinity,
    helpers: Helpers | None = None,
) -> list[Chart]:
    """Bisect, round by round, the charts whose bisection removes most of their distortion: a
    chart of at most ``GAIN_MAX_FACES`` faces is replaced by the pieces of its two halves (mapped
    as the stage maps any chart, :func:`_map_groups`) when that lowers the atlas's excess
    (:func:`_excess`) by at least ``min_split_gain`` per chart added and by at least
    ``GAIN_MIN_SHARE`` of the chart's own excess; the pieces may be bisected again next round. A
    chart whose bisection fails the test is kept and not tried again. Each bisection kept lowers
    the excess by ``min_split_gain`` or more, so there are at most ``excess / min_split_gain`` of
    them. ``V`` is in the stage's unit frame, the charts in mesh indices and units."""
    area = face_areas(V, F)
    tried = np.zeros(len(charts), dtype=bool)
    while True:
        ex = _excess(charts, area)
        nf = np.array([len(c.faces) for c in charts])
        go = ~tried & (ex >= cfg.min_split_gain) & (nf >= 2) & (nf <= GAIN_MAX_FACES)
        go &= _excess(charts, area, own=True) >= GAIN_MIN_EXCESS
        cand = np.flatnonzero(go)
        if len(cand) == 0:
            return charts
        halves = divide_many(
            affinity.mesh(), [charts[i].faces for i in cand], seed=seed, straighten=_STRAIGHTEN
        )
        groups = [[h for h in parts if len(h)] for parts in halves]
        order = np.concatenate([h for parts in groups for h in parts])
        bounds = np.r_[0, np.cumsum([len(h) for parts in groups for h in parts])]
        owner = np.repeat(np.arange(len(cand)), [len(parts) for parts in groups])
        labels = np.zeros(len(F), dtype=np.int64)
        labels[order] = np.repeat(np.arange(len(bounds) - 1), np.diff(bounds))
        skip = functools.partial(_hopeless, owner=owner, ex=ex[cand], area=area, cfg=cfg)
        mapped = _map_groups(
            V, F, labels, order, bounds, cfg, seed, size, affinity, helpers, skip=skip
        )
        now: list[list[Chart]] = [[c] for c in charts]  # what each chart becomes, in place
        done = tried.tolist()
        for k, i in enumerate(cand.tolist()):  # loop over the charts bisected
            if any(mapped[g] is None for g in np.flatnonzero(owner == k)):
                done[i] = True  # its bisection fails the test: not mapped to the end
                continue
            parent = charts[i]
            pieces = [
                dataclasses.replace(p, source=parent.source, depth=parent.depth + 1 + p.depth)
                for g in np.flatnonzero(owner == k) for p in mapped[g]
            ]  # fmt: skip
            gain = ex[i] - _excess(pieces, area).sum()
            if gain >= max(cfg.min_split_gain * (len(pieces) - 1), GAIN_MIN_SHARE * ex[i]):
                now[i] = pieces
            else:
                done[i] = True
        tried = np.repeat(done, [len(c) for c in now])
        charts = [c for chart in now for c in chart]


def _slit_cones(
    V: np.ndarray,
    F: np.ndarray,
    charts: list[Chart],
    cfg: SplitConfig,
    size: float,
    helpers: Helpers | None,
) -> list[Chart]:
    """Free the strongest cone of every chart whose angle distortion is above ``slit_above``,
    round by round (at most ``CONE_SLIT_ROUNDS``): the chart is cut along the shortest edge path
    from that cone to its rim (:func:`_cut_at_cones`) and solved again, all such charts in one
    batch (:func:`_solve_batch`). The slit chart replaces the chart when its map is kept
    (bijective, within the targets), its own distortion excess (``L2^2 - 1`` plus angle
    ``- 1``) is at most ``1 - CONE_SLIT_GAIN`` of the chart's and the atlas's (area-weighted,
    :func:`_excess`) falls by ``CONE_SLIT_MIN_GAIN`` or more. A chart keeps its faces and its
    place: no chart is added, the slit's edges become seams. ``V, F`` is the mesh in the
    stage's unit frame, the charts in mesh indices and units."""
    if cfg.slit_above is None:
        return charts
    charts = list(charts)
    area = face_areas(V, F)
    tried = np.zeros(len(charts), dtype=bool)
    for _ in range(CONE_SLIT_ROUNDS):
        cand = _cone_slit_candidates(charts, tried, area, cfg)
        tried[cand] = True
        cut = _cut_at_cones(
            V, [charts[i].vertices for i in cand], [charts[i].local_F for i in cand]
        )
        if cut is None:
            break
        slit = cand[cut.which]
        n_faces = np.diff(cut.fptr)
        maps = _solve_batch(
            cut.V, cut.F, cut.vert_chart, _stretch_limit(n_faces, cfg), cfg, helpers
        )
        q = maps.quality
        before = _excess([charts[i] for i in slit], np.empty(0), own=True)
        after = (q["l2_stretch"] ** 2 - 1) + (q["angle_distortion"] - 1)
        share = np.array([area[charts[i].faces].sum() for i in slit]) / area.sum()
        kept = q["bijective"] & _within_targets(
            q["angle_distortion"], q["l2_stretch"], n_faces, cfg
        )
        kept &= after <= (1 - CONE_SLIT_GAIN) * before
        kept &= share * (before - after) >= CONE_SLIT_MIN_GAIN
        records = quality_records(q)
        for j in np.flatnonzero(kept).tolist():  # loop over the slit charts kept
            i = int(slit[j])
            own, local_F, v = cut.piece(j)
            charts[i] = dataclasses.replace(
                charts[i], vertices=charts[i].vertices[own], local_F=local_F,
                uv=maps.uv[v] * size, quality=records[j],
            )  # fmt: skip
            tried[i] = False  # it may take another slit next round
    return charts


def _cone_slit_candidates(
    charts: list[Chart], tried: np.ndarray, area: np.ndarray, cfg: SplitConfig
) -> np.ndarray:
    """The charts :func:`_slit_cones` tries this round: not tried yet, solver's charts (planar
    and developable ones are exact) of ``STRETCH_MIN_FACES`` to ``CONE_SLIT_MAX_FACES`` faces
    over ``slit_above``, holding enough of the atlas's excess that removing ``CONE_SLIT_MOST``
    of it would gain ``CONE_SLIT_MIN_GAIN``."""
    nf = np.array([len(c.faces) for c in charts])
    cand = np.flatnonzero(~tried & (nf >= STRETCH_MIN_FACES) & (nf <= CONE_SLIT_MAX_FACES))
    solved = [i for i in cand.tolist() if charts[i].method == "hessian"]
    cand = np.array(
        [i for i in solved if charts[i].quality.angle_distortion > cfg.slit_above], np.int64
    )
    if len(cand) == 0:
        return cand
    return cand[_excess([charts[i] for i in cand], area) >= CONE_SLIT_MIN_GAIN / CONE_SLIT_MOST]


@dataclass(frozen=True)
class _ConeCuts:
    """Pieces cut open at their strongest cones (:func:`_cut_at_cones`), as one union ordered by
    piece: piece ``j`` (``which[j]`` of the lists given) has the vertices ``vptr[j] .. vptr[j +
    1]`` of ``V`` (``own``: each one's vertex in that piece, the slit's twice) and the faces
    ``fptr[j] .. fptr[j + 1]`` of ``F``."""

    which: np.ndarray
    V: np.ndarray
    F: np.ndarray
    own: np.ndarray
    vptr: np.ndarray
    fptr: np.ndarray

    @property
    def vert_chart(self) -> np.ndarray:
        return np.repeat(np.arange(len(self.which)), np.diff(self.vptr))

    def piece(self, j: int) -> tuple[np.ndarray, np.ndarray, slice]:
        """Piece ``j`` cut open: each new vertex's vertex in the piece, the faces on the new
        vertices, and the piece's rows of the union's vertices (of ``V``, of a map of it)."""
        v = slice(self.vptr[j], self.vptr[j + 1])
        return self.own[v], self.F[self.fptr[j] : self.fptr[j + 1]] - self.vptr[j], v


def _cut_at_cones(
    V: np.ndarray, vertices: list[np.ndarray], faces: list[np.ndarray]
) -> _ConeCuts | None:
    """The pieces (``vertices[k]``: the rows of ``V`` of piece ``k``'s vertices, ``faces[k]``
    its faces on them) that are disks with a cone of ``CONE_MIN_DEFECT`` or more at most
    ``CONE_SLIT_MAX_EDGES`` edges from the rim, each cut along that shortest slit
    (:func:`segparam.mesh.cone_slits`), or None if there is none. The pieces go as one union of
    their own vertices through the disk test, the slits and one
    :func:`segparam.mesh.cut_along`: each new vertex is a copy of one of the union's, the first
    copies in order and then the slits' second ones, which regrouped by piece is each piece's
    own cut, bit for bit."""
    if len(vertices) == 0:
        return None
    nv = np.array([len(v) for v in vertices])
    vstart = np.r_[0, np.cumsum(nv)[:-1]]
    Vu = np.concatenate([V[v] for v in vertices])
    Fu = np.concatenate([f + vstart[j] for j, f in enumerate(faces)])
    vert_chart = np.repeat(np.arange(len(vertices)), nv)
    face_chart = vert_chart[Fu[:, 0]]
    disks = disk_labels(Fu, face_chart, len(vertices))
    slits, _ = cone_slits(Vu, Fu, vert_chart, len(vertices), min_defect=CONE_MIN_DEFECT)
    take = np.flatnonzero(disks & np.array([0 < len(c) <= CONE_SLIT_MAX_EDGES for c in slits]))
    if len(take) == 0:
        return None
    rows = np.flatnonzero(np.isin(face_chart, take))
    F_cut, src = cut_along(Fu[rows], np.concatenate([slits[j] for j in take]))
    by_chart = np.argsort(vert_chart[src], kind="stable")
    new = np.empty(len(src), dtype=np.int64)
    new[by_chart] = np.arange(len(src))
    src = src[by_chart]
    vptr = np.r_[0, np.cumsum(np.bincount(vert_chart[src], minlength=len(vertices))[take])]
    fptr = np.r_[0, np.cumsum(np.bincount(face_chart[rows], minlength=len(vertices))[take])]
    own = src - vstart[vert_chart[src]]
    return _ConeCuts(take, Vu[src], new[F_cut], own, vptr, fptr)


def _hopeless(
    known_so_far: dict, *, owner: np.ndarray, ex: np.ndarray, area: np.ndarray, cfg: SplitConfig
) -> np.ndarray:
    """:func:`_split_for_gain`'s groups not worth mapping further: the bisection of their chart
    (``owner``, whose excess is ``ex``) fails the test whatever they become, by what its groups
    hold so far (``known_so_far``: group -> (pieces mapped, pieces still to map), after the
    batched pass and after each round): every piece still to come adds excess and a chart
    (excess is never negative). The atlas is the one mapping them all would give; the pass
    saves their rounds (brain-2k: 0.05 s of its 0.16 s after the batched pass)."""
    known = np.zeros(len(ex))
    count = np.bincount(owner, minlength=len(ex)).astype(np.float64)  # pieces, at least
    for g, (pieces, pending) in known_so_far.items():  # loop over the groups with news
        known[owner[g]] += _excess(pieces, area).sum()
        count[owner[g]] += len(pieces) + pending - 1
    bound = np.maximum(cfg.min_split_gain * (count - 1), GAIN_MIN_SHARE * ex)
    lost = ex - known < bound * (1 - 1e-9)  # a margin for the sums' rounding
    return lost[owner]


def _map_groups(
    V: np.ndarray,
    F: np.ndarray,
    labels: np.ndarray,
    order: np.ndarray,
    bounds: np.ndarray,
    cfg: SplitConfig,
    seed: int,
    size: float,
    affinity: _MeshAffinity,
    helpers: Helpers | None = None,
    skip: Callable[[dict], np.ndarray] | None = None,
) -> list[list[Chart] | None]:
    """The charts of each face group ``order[bounds[g] : bounds[g + 1]]`` (``labels[order]`` its
    group), mapped as :func:`parameterize_charts` maps segmentation charts (in bulk where it can,
    then round by round, in this process): in mesh indices and units; ``source`` and ``depth``
    are the group's and the depth below it. ``skip(known)``, given what the groups hold so far
    (group -> (charts mapped, pieces still to map); after the bulk pass, then after each round),
    says which groups not to map further: None for those."""
    n = len(bounds) - 1
    sources = [order[bounds[s] : bounds[s + 1]] for s in range(n)]
    sub = _submeshes(F, labels, order, bounds)
    rejected, bijective = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
    final = _bulk_charts(V, F, sub, order, bounds, cfg, size, rejected, bijective, helpers=helpers)
    mapped = {s: (final[s][0], 0) for s in final}
    skipped = np.zeros(n, dtype=bool) if skip is None else skip(mapped)
    rest = [s for s in range(n) if s not in final and not skipped[s]]
    give_up = None
    if skip is not None:

        def give_up(so_far: dict) -> set:
            """Of the groups in rounds (group -> (pieces so far in mesh indices, pending)),
            those to drop, judged with every group the bulk pass mapped."""
            lost = skip(mapped | so_far)
            return {s for s in so_far if lost[s]}

    results = _solve_in_rounds(
        V, F, rest, sources, sub, affinity, cfg, seed, size, rejected, bijective, None, 0, helpers,
        give_up=give_up,
    )  # fmt: skip
    out: list[list[Chart] | None] = [final[s][0] if s in final else None for s in range(n)]
    for s in rest:
        if s in results:
            out[s] = _in_mesh(results[s][0], sources[s], sub.of(s)[0], size)
    return out


def _in_mesh(
    pieces: list[Chart], faces: np.ndarray, vertices: np.ndarray, size: float
) -> list[Chart]:
    """A chart's pieces from :func:`_solve_source` (in the chart's own indices and the stage's
    unit frame) back in mesh indices and units: ``faces`` and ``vertices`` are the chart's."""
    return [
        dataclasses.replace(c, faces=faces[c.faces], vertices=vertices[c.vertices], uv=c.uv * size)
        for c in pieces
    ]


@dataclass(frozen=True)
class _Submeshes:
    """Every chart's own vertices and faces, for all charts at once.

    Chart ``s`` has the mesh vertices ``vertices[vptr[s] : vptr[s + 1]]`` (ascending) and the
    faces ``local_F[bounds[s] : bounds[s + 1]]`` in those local indices, in the order of
    ``order`` (the faces sorted by chart): what :func:`segparam.mesh.submesh` gives chart by chart.
    """

    vertices: np.ndarray
    vptr: np.ndarray
    local_F: np.ndarray
    bounds: np.ndarray

    def of(self, src: int) -> tuple[np.ndarray, np.ndarray]:
        """Chart ``src``'s ``(vertices, local_F)``."""
        v = self.vertices[self.vptr[src] : self.vptr[src + 1]]
        return v, self.local_F[self.bounds[src] : self.bounds[src + 1]]


def _submeshes(F: np.ndarray, labels: np.ndarray, order: np.ndarray, bounds: np.ndarray):
    """:class:`_Submeshes` of every chart: one sort of the (chart, vertex) pairs."""
    n_src = len(bounds) - 1
    nv = int(F.max()) + 1
    lab = labels[order]
    keys, inverse = np.unique((lab[:, None] * nv + F[order]).ravel(), return_inverse=True)
    vptr = np.searchsorted(keys // nv, np.arange(n_src + 1))
    local_F = inverse.reshape(-1, 3) - vptr[lab][:, None]
    return _Submeshes(keys % nv, vptr, local_F.astype(np.int64), bounds)


def _union(sub: _Submeshes, charts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The disjoint union of some charts: their mesh vertices, faces and vertex charts.

    Returns
    -------
    vertices : (k,) int64 ndarray
        Mesh vertex of every union vertex (chart by chart, as in :class:`_Submeshes`).
    F : (f, 3) int64 ndarray
        The charts' faces in union indices, chart by chart.
    vert_chart : (k,) int64 ndarray
        Position in ``charts`` of every union vertex's chart.
    """
    nv = sub.vptr[charts + 1] - sub.vptr[charts]
    nf = sub.bounds[charts + 1] - sub.bounds[charts]
    vert_chart = np.repeat(np.arange(len(charts)), nv)
    vstart = np.r_[0, np.cumsum(nv)[:-1]]
    v_idx = sub.vptr[charts][vert_chart] + np.arange(len(vert_chart)) - vstart[vert_chart]
    face_chart = np.repeat(np.arange(len(charts)), nf)
    fstart = np.r_[0, np.cumsum(nf)[:-1]]
    f_idx = sub.bounds[charts][face_chart] + np.arange(len(face_chart)) - fstart[face_chart]
    Fu = sub.local_F[f_idx] + vstart[face_chart][:, None]
    return sub.vertices[v_idx], Fu, vert_chart


def _project_union(V: np.ndarray, F: np.ndarray, vert_chart: np.ndarray, n_charts: int):
    """:func:`project_chart` of every chart of a disjoint union, all at once.

    Returns
    -------
    uv : (n, 2) float64 ndarray
    ok : (n_charts,) bool ndarray
        False where the area-weighted normal vanishes (the per-chart fallback takes those).
    """
    face_chart = vert_chart[F[:, 0]]
    N = face_normals(V, F) * face_areas(V, F)[:, None]
    n = np.stack([np.bincount(face_chart, N[:, j], minlength=n_charts) for j in range(3)], 1)
    length = np.linalg.norm(n, axis=1)
    ok = length >= 1e-300
    n = n / np.where(ok, length, 1.0)[:, None]
    b1, b2 = plane_basis(n)
    count = np.bincount(vert_chart, minlength=n_charts)
    mean = np.stack([np.bincount(vert_chart, V[:, j], minlength=n_charts) for j in range(3)], 1)
    X = V - (mean / np.maximum(count, 1)[:, None])[vert_chart]
    uv = np.stack([(X * b1[vert_chart]).sum(1), (X * b2[vert_chart]).sum(1)], axis=1)
    return uv, ok


#: A solver batch is shared with the helper processes (:class:`segparam.cores.Helpers`) in parts
#: of at least this many faces. Measured on the batches of brain-2k and brain-20k, two parts on
#: this 2-core machine against one call (min of 3 runs, the same maps): 1,945-19,263 faces
#: 0.097-0.437 s -> 0.069-0.297 s, 2,139 faces 0.092 -> 0.062 s, 1,268 faces 0.048 -> 0.045 s;
#: 739 and 342 faces slower (0.057 -> 0.058 s, 0.062 -> 0.072 s). (Two parts at once each take
#: about 70% of the whole's time here, not half: the two processes slow each other down.)
PART_MIN_FACES = 700
#: The helpers are forked for the first batch of at least this many faces (later batches are
#: shared from ``2 * PART_MIN_FACES`` faces): forking and starting them costs 0.05-0.09 s once
#: (brain-2k's first batch, 1,971 faces: 0.064 -> 0.155 s with the fork), which a batch of a few
#: thousand faces does not save.
FORK_MIN_FACES = 4_000


def _shares(helpers: Helpers | None, n_items: int, n_faces: int) -> int:
    """Into how many processes' shares to cut work of ``n_items`` charts or pieces and
    ``n_faces`` faces: up to ``helpers.jobs``, each share at least one item and
    ``PART_MIN_FACES`` faces, and 1 while the helpers are not started unless the work has
    ``FORK_MIN_FACES`` faces (1 without helpers)."""
    if helpers is None:
        return 1
    jobs = min(helpers.jobs, n_items, n_faces // PART_MIN_FACES)
    if jobs > 1 and not helpers.started and n_faces < FORK_MIN_FACES:
        return 1
    return jobs


def _solve_batch(
    V: np.ndarray,
    F: np.ndarray,
    vert_chart: np.ndarray,
    slim_below: np.ndarray | None,
    cfg: SplitConfig,
    helpers: Helpers | None,
) -> ChartMaps:
    """:func:`segparam.parameterize.solve_charts` of a union of charts (its layout: vertices and
    faces ordered by chart), cut by whole charts into up to ``helpers.jobs`` parts of about the
    same number of faces (each at least ``PART_MIN_FACES``; the helpers are started by a batch of
    ``FORK_MIN_FACES`` or more), solved side by side and put back together in order. A chart's
    map does not depend on the other charts of its call, so the result is the one call's, bit
    for bit."""
    n_charts = int(vert_chart[-1]) + 1
    face_chart = vert_chart[F[:, 0]]
    jobs = _shares(helpers, n_charts, len(F))
    kwargs = {"tangent": cfg.tangent, "refine": cfg.refine, "angle_weight": cfg.angle_weight}
    if jobs <= 1:
        return solve_charts(V, F, vert_chart, slim_below=slim_below, **kwargs)
    # the parts' chart bounds: each part ends with the chart that crosses its share of the faces
    ends = np.cumsum(np.bincount(face_chart, minlength=n_charts))
    cuts = np.searchsorted(ends, len(F) * np.arange(1, jobs) / jobs, side="right") + 1
    edges = np.r_[0, np.unique(np.clip(cuts, 1, n_charts - 1)), n_charts]
    vb, fb = np.searchsorted(vert_chart, edges), np.searchsorted(face_chart, edges)
    parts = []
    for k in range(len(edges) - 1):  # loop over the parts
        c, v, f = slice(*edges[k : k + 2]), slice(*vb[k : k + 2]), slice(*fb[k : k + 2])
        limits = None if slim_below is None else slim_below[c]
        parts.append((V[v], F[f] - vb[k], vert_chart[v] - edges[k], limits))
    maps = helpers.map(functools.partial(_solve_part, kwargs=kwargs), parts)
    return ChartMaps(
        uv=np.concatenate([m.uv for m in maps]),
        quality={k: np.concatenate([m.quality[k] for m in maps]) for k in maps[0].quality},
        refined=np.concatenate([m.refined for m in maps]),
        eigenvalues=np.concatenate([m.eigenvalues for m in maps]),
        starved=np.concatenate([m.starved for m in maps]),
    )


def _solve_part(
    V: np.ndarray,
    F: np.ndarray,
    vert_chart: np.ndarray,
    slim_below: np.ndarray | None,
    *,
    kwargs: dict,
) -> ChartMaps:
    """One part of :func:`_solve_batch` (a module-level function: it is sent to a helper)."""
    return solve_charts(V, F, vert_chart, slim_below=slim_below, **kwargs)


def _bulk_charts(
    V: np.ndarray,
    F: np.ndarray,
    sub: _Submeshes,
    order: np.ndarray,
    bounds: np.ndarray,
    cfg: SplitConfig,
    size: float,
    rejected: np.ndarray | None = None,
    bijective: np.ndarray | None = None,
    *,
    helpers: Helpers | None = None,
    project_only: np.ndarray | None = None,
    curvature: Callable[[], np.ndarray] | None = None,
    capped: np.ndarray | None = None,
) -> dict[int, tuple[list[Chart], bool]]:
    """The small segmentation charts that map on their first try, mapped all at once.

    What :func:`_try_piece` does to a chart at depth 0, for many charts in a few vectorized
    passes (topology from :func:`segparam.mesh.label_topology`, quality from
    :func:`segparam.parameterize.charts_quality`):

    * fewer than ``min_faces`` faces or ``MIN_POINTS`` vertices, and a disk or one triangle:
      projected onto its plane, kept if bijective (a triangle always): method ``"projection"``;
    * planar and a disk: projected, kept if bijective: ``"planar"``;
    * otherwise, with the ``"hessian"`` solver, at most ``BATCH_MAX_VERTICES`` vertices and
      everything :func:`segparam.parameterize.check_chart` asks: solved together with the others
      (:func:`segparam.parameterize.solve_charts`), kept if bijective and within
      ``max_distortion`` and ``max_stretch``: ``"hessian"``;
    * a tube (:func:`_tubes`) with two loops: cut open into a disk and solved with the others
      (what :func:`_opened` does alone); a tube of more loops is not tried.

    The charts ``project_only`` names (the split rounds' pieces past ``max_depth``) are taken as
    small ones, whatever their size, as :func:`_try_piece` takes them. With ``curvature`` (what
    gives each mesh face's :func:`segparam.mesh.curvature_shares`), the disks that are caps
    (:func:`_caps`) are not solved but rejected, and ``capped[chart]`` is set (when given).

    A chart that fails any of these is not in the result: the per-chart path maps or splits it,
    as before. Where :func:`_try_piece` could only fail the same way (a small chart whose
    projection folds, a chart the solver mapped outside the targets, a tube), ``rejected[chart]``
    is set (when given), so that the caller can split it without trying it again;
    ``bijective[chart]`` (when given) is set where the solver's map was bijective, kept or not.
    ``V`` is in the stage's unit frame; the charts returned are in mesh indices and units (``uv
    * size``).

    Returns
    -------
    dict
        Segmentation chart -> (its one chart, first-pass success).
    """
    n_src = len(bounds) - 1
    nf = np.diff(bounds)
    nv = np.diff(sub.vptr)
    small = (nf < cfg.min_faces) | (nv < MIN_POINTS)
    if project_only is not None:
        small |= project_only
    # Planar: every face normal within PLANAR_TOL of the chart's first face's.
    N = face_normals(V, F[order])  # only the faces of these charts (rounds pass few)
    lab = np.repeat(np.arange(n_src), nf)
    dev = np.abs(N - N[bounds[:-1]][lab]).max(axis=1)  # the last chart has faces: in range
    planar = np.zeros(n_src, dtype=bool)
    planar[nf > 0] = np.maximum.reduceat(dev, bounds[:-1][nf > 0]) < PLANAR_TOL
    solver = ~small & (nv <= min(BATCH_MAX_VERTICES, DENSE_LIMIT)) & (cfg.method == "hessian")
    cand = np.flatnonzero((nf > 0) & (small | planar | solver))
    if len(cand) == 0:
        return {}
    vertices, Fu, vert_chart = _union(sub, cand)
    topo = label_topology(Fu, vert_chart[Fu[:, 0]], len(cand))
    manifold = topo["edge_manifold"] & topo["vertex_manifold"] & (topo["components"] == 1)
    disk = manifold & (topo["loops"] >= 1) & (topo["euler"] == 2 - topo["loops"])
    Vu = V[vertices]
    out: dict[int, tuple[list[Chart], bool]] = {}

    def part(charts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The union of some of the charts (positions in ``cand``, ascending): vertex
        positions, faces and vertex charts (positions in ``charts``)."""
        keep = np.zeros(len(cand), dtype=bool)
        keep[charts] = True
        v_sel = np.flatnonzero(keep[vert_chart])
        remap = np.full(len(Vu), -1)
        remap[v_sel] = np.arange(len(v_sel))
        renum = np.full(len(cand), -1)
        renum[charts] = np.arange(len(charts))
        Fs = remap[Fu[keep[vert_chart[Fu[:, 0]]]]]
        return Vu[v_sel], Fs, renum[vert_chart[v_sel]]

    def emit(charts, vc, uv, q, keep, method) -> None:
        """Of a union of ``charts`` (positions in ``cand``) with vertex charts ``vc``, map ``uv``
        and quality ``q``, the charts where ``keep`` into ``out``, in mesh indices and units."""
        count = np.bincount(vc, minlength=len(charts))
        vend = np.cumsum(count)
        sel = np.flatnonzero(keep)
        first = method != "projection"  # as _solve_source: a projection is not a first-pass map
        for src, quality, a, b in zip(
            cand[charts[sel]].tolist(),
            quality_records(q, sel),
            (vend - count)[sel].tolist(),
            vend[sel].tolist(),
            strict=True,
        ):  # one object per chart: the result is a tuple of charts
            verts, local_F = sub.of(src)
            rows = order[bounds[src] : bounds[src + 1]]
            out[src] = ([Chart(rows, verts, local_F, uv[a:b] * size, quality, src, 0, method)],
                        first)  # fmt: skip

    # Projections: the small charts and the planar ones, in one pass.
    c_small, c_planar = small[cand], planar[cand] & ~small[cand]
    proj = np.flatnonzero((c_small & ((nf[cand] == 1) | disk)) | (c_planar & disk))
    planar_ok = np.zeros(len(cand), dtype=bool)
    if len(proj):
        Vp, Fp, vc = part(proj)
        uv, has_normal = _project_union(Vp, Fp, vc, len(proj))
        q = charts_quality(Vp, Fp, uv, vc, len(proj))
        uv, q = _refine_projections(Vp, Fp, vc, uv, q, has_normal & c_small[proj], cfg)
        single = c_small[proj] & (nf[cand][proj] == 1)  # a triangle: always kept
        fits = q["bijective"] & (
            ~c_small[proj]
            | _within_targets(q["angle_distortion"], q["l2_stretch"], nf[cand][proj], cfg)
        )
        ok = has_normal & (fits | single)
        planar_ok[proj[ok & c_planar[proj]]] = True
        emit(proj, vc, uv, q, ok & c_small[proj], "projection")
        emit(proj, vc, uv, q, ok & c_planar[proj], "planar")
        if rejected is not None:
            rejected[cand[proj[~ok & c_small[proj]]]] = True
    if rejected is not None:  # a small piece of 2+ faces that is not a disk: _try_piece splits it
        rejected[cand[c_small & (nf[cand] > 1) & ~disk]] = True
    # The solver, on the small non-planar charts (and planar ones whose projection folds).
    # (A chart too small for the neighbourhoods the solver needs comes back starved and is
    # rejected, as the solver alone would raise on it: the brain-2k's 8-12-face pieces of the
    # split rounds were solved one by one for want of MAX_EXTEND spare vertices, most fine.)
    go = solver[cand] & manifold & (topo["loops"] >= 1) & ~planar_ok & ~(c_planar & ~disk)
    # Developable disks (a cylinder's side, a cone's): unrolled, the exact isometry, not solved.
    flat = go & disk
    if flat.any():
        flat &= developable(Vu, Fu, vert_chart, len(cand), euler=1)
    flat = np.flatnonzero(flat)
    if len(flat):
        Vd, Fd, vd = part(flat)
        uv, q, kept = _unroll_checked(Vd, Fd, vd, len(flat))
        emit(flat, vd, uv, q, kept, "developable")
        go[flat[kept]] = False
    one_loop = disk & (topo["loops"] == 1)
    if curvature is not None and (go & one_loop).any():  # caps: cut without a solve

        def share() -> np.ndarray:
            return np.bincount(lab, weights=curvature()[order], minlength=n_src)[cand]

        cut = _caps(Vu, Fu, vert_chart, len(cand), share, nf[cand], cfg, go & one_loop)
        go &= ~cut
        if rejected is not None:
            rejected[cand[cut]] = True
        if capped is not None:
            capped[cand[cut]] = True
    holed = np.flatnonzero(go & (topo["loops"] >= 2))
    # Tubes are not solved as they are: one of two loops is cut open into a disk and solved with
    # the others (as _opened does alone), one of more loops is split.
    annulus = topo["loops"] == 2
    opened, cuts = np.zeros(0, dtype=np.int64), []
    if len(holed):
        Vh, Fh, vh = part(holed)
        tube = holed[_tubes(Vh, Fh, vh[Fh[:, 0]], len(holed))]
        go[tube] = False
        if rejected is not None:
            rejected[cand[tube[~annulus[tube]]]] = True
        for c in tube[annulus[tube]].tolist():  # loop over the tubes (a few): one cut each
            verts, local_F = sub.of(int(cand[c]))
            cut = _tube_cut(V[verts], local_F)
            if cut is None:  # too long a strip once open: split, as _try_piece would
                if rejected is not None:
                    rejected[cand[c]] = True
                continue
            F_cut, copy_of = cut_along(local_F, cut)
            unrolled = _unrolled(V[verts[copy_of]], F_cut, tube=True)
            if unrolled is not None:  # a developable tube (a drilled hole's wall): unrolled
                uv, quality = unrolled
                rows = order[bounds[cand[c]] : bounds[cand[c] + 1]]
                out[int(cand[c])] = ([Chart(rows, verts[copy_of], F_cut, uv * size, quality,
                                            int(cand[c]), 0, "developable")], True)  # fmt: skip
                continue
            if len(copy_of) <= DENSE_LIMIT:  # else _try_piece solves it alone
                opened = np.r_[opened, c]
                cuts.append((V[verts[copy_of]], F_cut, copy_of))
    take = np.flatnonzero(go)
    if len(take) or len(opened):  # one solver batch: the charts as they are, then the tubes cut
        Vs, Fs, vc = part(take)
        n_take = len(take)
        nv = np.r_[np.bincount(vc, minlength=n_take), [len(c[0]) for c in cuts]].astype(np.int64)
        vstart = np.r_[0, np.cumsum(nv)[:-1]]
        Vs = np.concatenate([Vs] + [c[0] for c in cuts])
        Fs = np.concatenate([Fs] + [c[1] + vstart[n_take + j] for j, c in enumerate(cuts)])
        vc = np.repeat(np.arange(len(nv)), nv)
        n_faces = np.r_[nf[cand][take], nf[cand][opened]]
        try:
            maps = _solve_batch(Vs, Fs, vc, _stretch_limit(n_faces, cfg), cfg, helpers)
        except (InvalidMeshError, np.linalg.LinAlgError) as exc:  # not expected: one by one
            log.debug("batched solver failed (%s); solving %d charts one by one", exc, len(nv))
            return out
        q = maps.quality
        # a new array: ``&=`` on q["bijective"] itself would rewrite the maps' quality
        ok = q["bijective"] & _within_targets(q["angle_distortion"], q["l2_stretch"], n_faces, cfg)
        emit(take, vc, maps.uv, q, ok[:n_take], "hessian")
        for j, c in enumerate(opened.tolist()):  # loop over the tubes cut open: their charts
            k, src = n_take + j, int(cand[c])
            if ok[k]:
                verts, _ = sub.of(src)
                rows = order[bounds[src] : bounds[src + 1]]
                uv = maps.uv[vstart[k] : vstart[k] + nv[k]] * size
                _, F_cut, copy_of = cuts[j]
                quality = quality_records(q, [k])[0]
                out[src] = ([Chart(rows, verts[copy_of], F_cut, uv, quality, src, 0, "hessian")],
                            True)  # fmt: skip
        if rejected is not None:
            rejected[cand[np.r_[take, opened][~ok]]] = True
        if bijective is not None:
            bijective[cand[np.r_[take, opened][q["bijective"]]]] = True
    return out


def _refine_projections(
    V: np.ndarray,
    F: np.ndarray,
    vert_chart: np.ndarray,
    uv: np.ndarray,
    q: dict[str, np.ndarray],
    which: np.ndarray,
    cfg: SplitConfig,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """With ``refine="slim"``, the refinement (:func:`segparam.refine.slim_refine`) of the
    bijective projections among the charts ``which`` of a disjoint union, kept where still
    bijective: the projection of a small piece of a curved surface is a valid start, but its
    stretch can be far from the least (a 4-face piece of the realistic 2k brain: L2 2.24)."""
    go = which & q["bijective"] & (q["n_flipped"] == 0) & (q["n_degenerate"] == 0)
    if cfg.refine != "slim" or not go.any():
        return uv, q
    n = len(go)
    uv_s, moved = slim_refine(
        V, F, uv, vert_chart=vert_chart, n_charts=n, charts=go, angle_weight=cfg.angle_weight
    )
    if not moved.any():
        return uv, q
    q_s = charts_quality(V, F, uv_s, vert_chart, n)
    use = (moved > 0) & q_s["bijective"]
    q = {k: np.where(use, q_s[k], q[k]) for k in q}
    return np.where(use[vert_chart][:, None], uv_s, uv), q


class _MeshAffinity:
    """The crease-aware face affinity (:func:`segment.face_affinity`) that splits failing charts.

    It is normalized over the whole mesh, so it is built once for the mesh, on first use (most
    runs split no chart), and every chart gets its restriction: a split does not depend on
    ``n_jobs``.
    """

    def __init__(self, V: np.ndarray, F: np.ndarray, W: sp.csr_matrix | None = None) -> None:
        self._V, self._F = V, F
        self._W = W

    def mesh(self) -> sp.csr_matrix:
        """The affinity of the whole mesh."""
        if self._W is None:
            self._W = face_affinity(self._V, self._F)
        return self._W

    def restricted(self, faces: np.ndarray) -> sp.csr_matrix:
        """The affinity among ``faces`` (mesh face indices), in their order."""
        return self.mesh()[faces][:, faces]

    def of_chart(self, faces: np.ndarray, *, now: bool) -> Callable[[], sp.csr_matrix]:
        """What :func:`_solve_source` calls for a chart's affinity when it must split the chart:
        restricted when called (``now=False``), or already restricted (``now=True``, for a
        worker process, which cannot reach the mesh)."""
        if now:
            return functools.partial(_given, self.restricted(faces))
        return functools.partial(self.restricted, faces)


def _given(W: sp.csr_matrix) -> sp.csr_matrix:
    return W


def _within_targets(angle, l2, n_faces, cfg: SplitConfig):
    """Whether charts with these angle distortions, L2 stretches and face counts meet the
    config's targets (``max_distortion``; ``max_stretch`` from ``STRETCH_MIN_FACES`` faces up,
    ``SMALL_CHART_MAX_STRETCH`` below; a missing target is met)."""
    ok = np.ones(np.shape(angle), dtype=bool)
    if cfg.max_distortion is not None:
        ok &= np.asarray(angle) <= cfg.max_distortion
    if cfg.max_stretch is not None:
        ok &= np.asarray(l2) <= _stretch_limit(n_faces, cfg)
    return ok


def _stretch_limit(n_faces, cfg: SplitConfig):
    """The L2 stretch charts of these face counts must meet (``max_stretch``, or
    ``SMALL_CHART_MAX_STRETCH`` under ``STRETCH_MIN_FACES`` faces), None without a target."""
    if cfg.max_stretch is None:
        return None
    small = np.asarray(n_faces) < STRETCH_MIN_FACES
    return np.where(small, max(cfg.max_stretch, SMALL_CHART_MAX_STRETCH), cfg.max_stretch)


def _caps(
    V: np.ndarray,
    F: np.ndarray,
    vert_chart: np.ndarray,
    n_charts: int,
    share: Callable[[], np.ndarray],
    n_faces: np.ndarray,
    cfg: SplitConfig,
    disks: np.ndarray,
) -> np.ndarray:
    """Per chart of a disjoint union (``vert_chart``: each vertex's chart), whether it is one of
    the ``disks`` that will miss the stretch target: a cap (``CAP_CURVATURE``, ``CAP_INNER``,
    ``CAP_ONE_SIGN``), a disk holding so much positive curvature inside that it will, whatever
    saddles it holds besides (``CAP_NET``), or one whose least-distorting conformal flattening
    stretches too much (``CONFORMAL_STRETCH_CUT``): the split stage cuts those without solving
    them. ``share()``: each chart's curvature with its border's share
    (:func:`segparam.mesh.curvature_shares` summed over its faces), asked for only when some
    chart holds enough curvature inside. Only under a stretch target of at most
    ``MAX_STRETCH``, where the bounds were measured."""
    limit = _stretch_limit(n_faces, cfg)
    if limit is None:
        return np.zeros(n_charts, dtype=bool)
    net, absolute = inner_curvature(V, F, vert_chart, n_charts)
    within = disks & (limit <= MAX_STRETCH)
    folded = within & (net >= CAP_NET)  # whatever saddles it holds besides
    inside = within & ~folded & (net >= CAP_INNER) & (net >= CAP_ONE_SIGN * absolute)
    if inside.any():
        inside &= share() >= CAP_CURVATURE
    rest = within & ~folded & ~inside
    if rest.any():
        rest &= _conformal_stretch(V, F, vert_chart, n_charts, rest) >= CONFORMAL_STRETCH_CUT
    return folded | inside | rest


def _conformal_stretch(
    V: np.ndarray, F: np.ndarray, vert_chart: np.ndarray, n_charts: int, which: np.ndarray
) -> np.ndarray:
    """Per chart of a disjoint union, the L2 stretch (Sander's) of its conformal flattening with
    the least area distortion, for the disks ``which`` (1 for the others).

    A conformal flattening scales the metric by ``exp(2 u)``, where ``L u = K`` inside (``L``
    the cotangent Laplacian, ``K`` the inner vertices' angle defects: the flat metric's
    curvature is 0); of all of them, ``u = 0`` on the boundary spreads the least area distortion
    (Sawhney and Crane's boundary first flattening keeps the boundary's lengths). A face whose
    area scales by ``s`` then stretches by ``1 / sqrt(s)`` both ways, and at equal total areas
    the chart's L2 stretch is ``sqrt(sum(A / s) sum(A s)) / sum(A)`` (1 for an isometry, by
    Cauchy-Schwarz). One sparse Cholesky factorization for all of the disks at once.

    References
    ----------
    R. Sawhney, K. Crane, Boundary First Flattening, ACM TOG 37(1), 2017.
    """
    out = np.ones(n_charts)
    face_chart = vert_chart[F[:, 0]]
    sel = which[face_chart]
    Fw, fc = F[sel], face_chart[sel]
    angles = corner_angles(V, Fw)
    edge_index = edges(Fw)
    inner = interior_vertices(Fw, len(V), edge_index=edge_index)
    K = interior_defect(V, Fw, angles=angles, edge_index=edge_index, interior=inner)[0]
    u = np.zeros(len(V))
    if inner.any():
        # the rows and columns of the inner vertices only: the rim's u is 0
        L = cotan_laplacian(V, Fw, angles=angles, edge_index=edge_index, keep=inner)
        try:
            u[inner] = spd_solver(L)(K[inner])
        except (ArithmeticError, RuntimeError, np.linalg.LinAlgError):  # singular: no bound
            return out
        if not np.isfinite(u).all():
            return out
    # a face's area factor; the clip only keeps a degenerate piece's factor finite (it is cut)
    s = np.exp(np.clip(2.0 * u[Fw].mean(axis=1), -50.0, 50.0))
    A = face_areas(V, Fw)
    total = np.bincount(fc, weights=A, minlength=n_charts)
    shrink = np.bincount(fc, weights=A / s, minlength=n_charts)
    grow = np.bincount(fc, weights=A * s, minlength=n_charts)
    out[which] = np.sqrt(shrink[which] * grow[which]) / total[which]
    return out


def _curvature_source(
    V: np.ndarray, F: np.ndarray, given: np.ndarray | None, cfg: SplitConfig
) -> Callable[[], np.ndarray] | None:
    """What gives each face's curvature share to :func:`_caps`: ``given``, or
    :func:`segparam.mesh.curvature_shares` computed on first call (6 ms at 20k faces, 0.6 s at
    1M: most meshes have no cap); None when no chart can be a cap under ``cfg`` (a stretch
    target above ``MAX_STRETCH``, or none)."""
    if cfg.max_stretch is None or cfg.max_stretch > MAX_STRETCH:
        return None
    if given is not None:
        return functools.partial(np.asarray, given, dtype=np.float64)
    return functools.cache(functools.partial(curvature_shares, V, F))


def _pieces_capped(
    V: np.ndarray,
    F: np.ndarray,
    pieces: list[np.ndarray],
    curvature: Callable[[], np.ndarray],
    cfg: SplitConfig,
) -> np.ndarray:
    """:func:`_caps` of disjoint pieces of the mesh (their mesh face indices), the ones that are
    disks: the few pieces a split round solves alone."""
    sizes = np.array([len(p) for p in pieces])
    order, bounds = np.concatenate(pieces), np.r_[0, np.cumsum(sizes)]
    labels = np.zeros(len(F), dtype=np.int64)
    labels[order] = np.repeat(np.arange(len(pieces)), sizes)
    vertices, Fu, vert_chart = _union(_submeshes(F, labels, order, bounds), np.arange(len(pieces)))
    disk = disk_labels(Fu, vert_chart[Fu[:, 0]], len(pieces), holes=False)

    def share() -> np.ndarray:
        return np.add.reduceat(curvature()[order], bounds[:-1])

    return _caps(V[vertices], Fu, vert_chart, len(pieces), share, sizes, cfg, disk)


def _tubes(V: np.ndarray, F: np.ndarray, face_chart: np.ndarray, n_charts: int) -> np.ndarray:
    """Per chart of a disjoint union (every chart its own vertices): whether it has two or more
    boundary loops and each turns by less than ``TUBE_TURNING`` in total. Loops are the pieces
    of the boundary graph (a manifold boundary: where two loops touch they count as one, and
    the chart is not called a tube)."""
    out = np.zeros(n_charts, dtype=bool)
    B = boundary_edges(F)
    if len(B) == 0:
        return out
    angle_sum = np.bincount(F.ravel(), weights=corner_angles(V, F).ravel(), minlength=len(V))
    verts, _, n_loops, loop = boundary_pieces(B)
    turning = np.bincount(loop, weights=np.pi - angle_sum[verts], minlength=n_loops)
    vert_chart = np.empty(len(V), dtype=np.int64)
    vert_chart[F] = face_chart[:, None]
    loop_chart = np.empty(n_loops, dtype=np.int64)
    loop_chart[loop] = vert_chart[verts]
    loops = np.bincount(loop_chart, minlength=n_charts)
    turned = np.bincount(loop_chart, weights=np.abs(turning) >= TUBE_TURNING, minlength=n_charts)
    return (loops >= 2) & (turned == 0)


def _piece_vertex_counts(sub: _Submeshes, srcs: list[int], faces: list[np.ndarray]) -> np.ndarray:
    """How many vertices each piece uses: piece ``k`` is the faces ``faces[k]`` (chart-local
    indices) of chart ``srcs[k]``. One ``np.unique`` of the pieces' corners, each piece's vertex
    numbers offset past the ones before, instead of one per piece (the 600 sphere halves' round:
    1,200 calls)."""
    srcs_a = np.asarray(srcs, dtype=np.int64)
    sizes = np.array([len(f) for f in faces])
    rows = np.concatenate(faces) + np.repeat(sub.bounds[srcs_a], sizes)  # rows of sub.local_F
    n_vertices = sub.vptr[srcs_a + 1] - sub.vptr[srcs_a]
    offset = np.r_[0, np.cumsum(n_vertices)[:-1]]
    distinct = np.unique(sub.local_F[rows] + np.repeat(offset, sizes)[:, None])
    piece = np.searchsorted(offset, distinct, side="right") - 1
    return np.bincount(piece, minlength=len(srcs))


def _solve_in_rounds(
    V: np.ndarray,
    F: np.ndarray,
    rest: list[int],
    sources: list[np.ndarray],
    sub: _Submeshes,
    affinity: _MeshAffinity,
    cfg: SplitConfig,
    seed: int,
    size: float,
    bulk_rejected: np.ndarray,
    bulk_bijective: np.ndarray,
    progress: Callable[[int], None] | None,
    done: int,
    helpers: Helpers | None = None,
    give_up: Callable[[dict], set] | None = None,
    curvature: Callable[[], np.ndarray] | None = None,
) -> dict[int, tuple[list[Chart], bool, bool]]:
    """:func:`_solve_source` for every chart in `rest`, in one process, a split depth at a time.

    Each round tries every piece left: the small ones (at most ``BATCH_MAX_VERTICES`` vertices)
    all at once through :func:`_bulk_charts` (those past ``max_depth`` projected only, as
    :func:`_try_piece` does), the others one by one (:func:`_try_piece`); the pieces that fail
    are bisected, all at once (:func:`segparam.segment.divide_many`), for the next round. The
    pieces a split makes are mostly small, and one solver call each cost ~20 ms of set-up
    (measured on the plate's hole walls and the cortex with a stretch target). A chart the bulk
    pass already rejected (``bulk_rejected``) is bisected at once. Returns what
    :func:`_solve_source` returns, per chart: pieces in chart-local indices and units, sorted as
    its depth-first bisection would emit them. ``give_up(so_far)``, after each round that leaves
    pieces to map (chart -> (its pieces so far, in mesh face indices, and how many are left)),
    names charts to drop: their pieces are not mapped further and they are not in the result.
    With ``curvature`` (what gives :func:`segparam.mesh.curvature_shares` of the mesh), the caps
    (:func:`_caps`) among the pieces are bisected without a solve, in bulk or alone.
    """
    m = len(F)
    pos = np.empty(m, dtype=np.int64)  # each face's index in its chart's face list
    for src in rest:  # loop over the charts left: index arrays
        pos[sources[src]] = np.arange(len(sources[src]))
    pieces: dict[int, list[tuple[tuple, Chart]]] = {src: [] for src in rest}
    first = dict.fromkeys(rest, False)
    # (chart, faces in chart-local indices, depth, path of bisection choices, bulk tried it)
    pending = [(src, np.arange(len(sources[src])), 0, (), bool(bulk_rejected[src])) for src in rest]
    untried: set = set()  # the charts whose first piece (depth 0) was cut without a solve
    open_pieces = dict.fromkeys(rest, 1)
    dropped: set = set()
    while pending:
        nverts = _piece_vertex_counts(
            sub, [src for src, *_ in pending], [f for _, f, *_ in pending]
        )
        batch = [
            k for k, (_, _, depth, _, tried) in enumerate(pending)
            if depth > 0 and not tried and nverts[k] <= BATCH_MAX_VERTICES
        ]  # fmt: skip
        mapped, rejected = {}, np.zeros(len(batch), dtype=bool)
        if batch:
            deep = np.array([pending[k][2] > cfg.max_depth for k in batch])  # projected only
            order = np.concatenate([sources[pending[k][0]][pending[k][1]] for k in batch])
            bounds = np.r_[0, np.cumsum([len(pending[k][1]) for k in batch])]
            labels = np.zeros(m, dtype=np.int64)
            labels[order] = np.repeat(np.arange(len(batch)), np.diff(bounds))
            sub_b = _submeshes(F, labels, order, bounds)
            got = _bulk_charts(
                V, F, sub_b, order, bounds, cfg, size, rejected, helpers=helpers,
                project_only=deep, curvature=curvature,
            )  # fmt: skip
            mapped = {batch[i]: got[i][0][0] for i in got}
        rejected_at = {batch[i] for i in np.flatnonzero(rejected)}
        # the pieces the solver takes alone (big ones, and the first try of a segmentation chart)
        alone = [
            k for k, (*_, tried) in enumerate(pending)
            if k not in mapped and not (tried or k in rejected_at)
        ]  # fmt: skip
        # the caps among them (deeper pieces are only projected): cut without a solve
        solvable = [k for k in alone if pending[k][2] <= cfg.max_depth]
        if curvature is not None and solvable:
            capped = _pieces_capped(
                V, F, [sources[pending[k][0]][pending[k][1]] for k in solvable], curvature, cfg
            )
            rejected_at |= {k for k, c in zip(solvable, capped, strict=True) if c}
            untried |= {pending[k][0] for k, c in zip(solvable, capped, strict=True)
                        if c and pending[k][2] == 0}  # fmt: skip
            alone = [k for k in alone if k not in rejected_at]
        tasks = [(V[sub.of(src)[0]], sub.of(src)[1], faces, src, depth)
                 for src, faces, depth, *_ in (pending[k] for k in alone)]  # fmt: skip
        tried_alone = dict(zip(alone, _try_pieces(tasks, cfg, seed, helpers), strict=True))
        nxt, cut = [], []
        for k, (src, faces, depth, path, tried) in enumerate(pending):  # loop over pieces
            vertices, local_F = sub.of(src)
            status: dict = {}
            if k in mapped:  # back from mesh to chart-local indices and units
                c = mapped[k]
                chart = dataclasses.replace(
                    c, faces=pos[c.faces], vertices=np.searchsorted(vertices, c.vertices),
                    uv=c.uv / size, source=src, depth=depth,
                )  # fmt: skip
            elif tried or k in rejected_at:
                chart = None
                status["bijective"] = depth == 0 and bool(bulk_bijective[src])
            else:
                chart, status = tried_alone[k]
            if depth == 0:
                first[src] = _first_pass(chart, status)
            open_pieces[src] -= 1
            if chart is not None:
                pieces[src].append((path, chart))
            else:
                cut.append((src, faces, depth, path))
        # Knob-like pieces that failed after a bisection: a slit before another bisection.
        deep = [k for k, (_, _, depth, _) in enumerate(cut) if depth >= SLIT_MIN_DEPTH]
        tries = []
        for k in deep:  # loop over the deep failed pieces: each with its chart's mesh
            src, faces, depth, _ = cut[k]
            vertices, local_F = sub.of(src)
            tries.append((V[vertices], local_F, faces, src, depth))
        slit = dict(zip(deep, _slit_charts(tries, cfg, seed, helpers), strict=True))
        for k, chart in slit.items():
            if chart is not None:
                pieces[cut[k][0]].append((cut[k][3], chart))
        cut = [piece for k, piece in enumerate(cut) if slit.get(k) is None]
        # The pieces that failed, all cut at once (in mesh face indices, back to chart-local).
        groups = [sources[src][faces] for src, faces, _, _ in cut]
        for (src, _, depth, path), parts in zip(
            cut,
            divide_many(affinity.mesh(), groups, seed=seed, straighten=_STRAIGHTEN) if cut else [],
            strict=True,
        ):  # loop over the pieces cut
            parts = [pos[p] for p in parts if len(p)]
            nxt.extend((src, p, depth + 1, (*path, i), False) for i, p in enumerate(parts))
            open_pieces[src] += len(parts)
        if progress is not None:
            for src in dict.fromkeys(src for src, *_ in pending):  # charts of this round
                if open_pieces[src] == 0:
                    done += 1
                    progress(done)
        if give_up is not None and nxt:
            so_far = {
                src: ([dataclasses.replace(c, faces=sources[src][c.faces]) for _, c in pieces[src]],
                      open_pieces[src])
                for src in dict.fromkeys(src for src, *_ in nxt)
            }  # fmt: skip
            dropped |= give_up(so_far)
            nxt = [piece for piece in nxt if piece[0] not in dropped]
        pending = nxt
    return {src: ([c for _, c in sorted(pieces[src], key=lambda t: t[0])], first[src],
                  src in untried)
            for src in rest if src not in dropped}  # fmt: skip


def _solve_source(
    V: np.ndarray,
    F: np.ndarray,
    affinity: Callable[[], sp.csr_matrix],
    src: int,
    cfg: SplitConfig,
    seed: int,
    shares: np.ndarray | None = None,
) -> tuple[list[Chart], bool, bool]:
    """Map one segmentation chart, bisecting the pieces that fail (the per-chart task).

    ``V, F`` are the chart's own vertices and faces; ``affinity()`` gives its face affinity
    (:meth:`_MeshAffinity.of_chart`; called only if the chart must be split). With ``shares``
    (its faces' :func:`segparam.mesh.curvature_shares` in the mesh), the caps (:func:`_caps`)
    are bisected without a solve, as :func:`_solve_in_rounds` does. Returns the bijective
    pieces, in chart-local indices, whether the first try succeeded, and whether the chart was
    cut without a try.
    """
    stack = [(np.arange(len(F)), 0)]
    pieces: list[Chart] = []
    first = untried = False
    W = None
    while stack:
        faces, depth = stack.pop()
        status: dict = {}
        capped = (
            shares is not None
            and depth <= cfg.max_depth  # deeper pieces are only projected (_try_piece)
            and bool(_pieces_capped(V, F, [faces], lambda: shares, cfg)[0])
        )
        chart = None if capped else _try_piece(V, F, faces, src, depth, cfg, seed, status)
        if depth == 0:
            first, untried = _first_pass(chart, status), capped
        elif chart is None:  # as _solve_in_rounds: a slit before another bisection
            chart = _slit_open(V, F, faces, src, depth, cfg, seed)
        if chart is not None:
            pieces.append(chart)
            continue
        if W is None:
            W = affinity()
        parts = divide(W, faces, seed=seed, straighten=_STRAIGHTEN)
        stack.extend((p, depth + 1) for p in reversed(parts) if len(p))
    return pieces, first, untried


def _try_pieces(tasks: list[tuple], cfg: SplitConfig, seed: int, helpers: Helpers | None) -> list:
    """:func:`_try_piece` of every ``(V, F, faces, src, depth)`` in ``tasks``: ``[(chart or None,
    status)]``, in order. With helpers (once started, or for ``FORK_MIN_FACES`` faces or more),
    the pieces are dealt to the processes largest first, each to the least loaded (faces), and
    solved side by side: each piece's result is its own, whichever process solves it."""
    # A developable piece unrolls in one pass over its faces (segparam.unfold): no solver work
    # to share, and forking a helper for it cost the pipe of bench_atlas.py more than it saved.
    sizes = np.array(
        [0 if _developable_piece(V, F, faces) else len(faces) for V, F, faces, *_ in tasks],
        dtype=np.int64,
    )  # loop over the pieces solved alone: a few
    jobs = _shares(helpers, len(tasks), int(sizes.sum()))
    if jobs <= 1:
        return _try_all(tasks, cfg=cfg, seed=seed)
    load, owner = np.zeros(jobs, dtype=np.int64), np.empty(len(tasks), dtype=np.int64)
    for i in np.argsort(-sizes, kind="stable").tolist():  # loop over the few pieces: deal them
        owner[i] = int(np.argmin(load))
        load[owner[i]] += sizes[i]
    groups = [np.flatnonzero(owner == j) for j in range(jobs)]
    done = helpers.map(
        functools.partial(_try_all, cfg=cfg, seed=seed), [([tasks[i] for i in g],) for g in groups]
    )
    out: list = [None] * len(tasks)
    for g, results in zip(groups, done, strict=True):
        for i, result in zip(g.tolist(), results, strict=True):
            out[i] = result
    return out


def _developable_piece(V: np.ndarray, F: np.ndarray, faces: np.ndarray) -> bool:
    """Whether the piece ``F[faces]`` of a chart (vertices ``V``) will likely unroll rather
    than go to the solver: developable (:func:`segparam.unfold.developable`), a strip one
    triangle wide included (a hole's wall; a strip of a curved surface is small work anyway).
    An estimate of the work, for dealing the pieces out only."""
    one = np.zeros(len(V), dtype=np.int64)
    return bool(developable(V, F[faces], one, 1, strips=True, euler=0)[0])  # a disk or a tube


def _try_all(tasks: list[tuple], *, cfg: SplitConfig, seed: int) -> list:
    """:func:`_try_pieces`' work in one process (module level: it is sent to a helper)."""
    out = []
    for V, F, faces, src, depth in tasks:  # loop over the pieces of one process
        status: dict = {}
        out.append((_try_piece(V, F, faces, src, depth, cfg, seed, status), status))
    return out


def _first_pass(chart: Chart | None, status: dict) -> bool:
    """Whether a chart's first try was a first-pass success: the solver's map was bijective,
    kept or split for a target (``status`` from :func:`_try_piece`); a projection is not."""
    return (chart is not None and chart.method != "projection") or status.get("bijective", False)


def _try_piece(
    V: np.ndarray,
    F: np.ndarray,
    faces: np.ndarray,
    src: int,
    depth: int,
    cfg: SplitConfig,
    seed: int,
    status: dict | None = None,
) -> Chart | None:
    """A bijective chart for these faces, or None if the piece must be split. ``status`` (when
    given) gets ``"bijective"``: whether the solver's map was bijective, within the targets or
    not (a first-pass success in the paper's sense)."""
    vertices, local_F = submesh(F, faces)
    Vl = V[vertices]
    small = len(faces) < cfg.min_faces or len(vertices) < MIN_POINTS
    if not small and depth <= cfg.max_depth:
        N = face_normals(Vl, local_F)
        if np.abs(N - N[0]).max() < PLANAR_TOL:
            uv = project_chart(Vl, local_F)
            try:
                quality = chart_quality(Vl, local_F, uv)
            except InvalidMeshError:  # a pinched boundary: not a disk, the solver says why
                quality = None
            if quality is not None and quality.bijective:
                return Chart(faces, vertices, local_F, uv, quality, src, depth, "planar")
        if _tubes(Vl, local_F, np.zeros(len(local_F), dtype=np.int64), 1)[0]:
            log.debug("chart %d depth %d: a tube (TUBE_TURNING), cut open or split", src, depth)
            return _opened(Vl, local_F, faces, vertices, src, depth, cfg, seed, status)
        unrolled = _unrolled(Vl, local_F)
        if unrolled is not None:
            if status is not None:
                status["bijective"] = True
            return Chart(faces, vertices, local_F, *unrolled, src, depth, "developable")
        try:
            result = _solved(Vl, local_F, len(faces), cfg, seed)
        except InvalidMeshError as exc:  # not a disk (e.g. a half that pinches): split it
            log.debug("chart %d depth %d: %s", src, depth, exc)
            return None
        if status is not None:
            status["bijective"] = bool(result.bijective)
        if _kept(result, len(faces), cfg):
            return Chart(
                faces, vertices, local_F, result.uv, result.quality, src, depth, result.method
            )
        return None
    if len(faces) > 1 and not is_disk(local_F):
        return None
    uv = project_chart(Vl, local_F)
    quality = chart_quality(Vl, local_F, uv)
    if quality.bijective and len(faces) > 1 and cfg.refine == "slim":
        uv_s, moved = slim_refine(Vl, local_F, uv, angle_weight=cfg.angle_weight)
        q_s = chart_quality(Vl, local_F, uv_s) if moved[0] else None
        if q_s is not None and q_s.bijective:
            uv, quality = uv_s, q_s
    if len(faces) == 1 or (
        quality.bijective
        and bool(_within_targets(quality.angle_distortion, quality.l2_stretch, len(faces), cfg))
    ):
        return Chart(faces, vertices, local_F, uv, quality, src, depth, "projection")
    return None


def _unrolled(
    V: np.ndarray, F: np.ndarray, *, tube: bool = False
) -> tuple[np.ndarray, ChartQuality] | None:
    """A developable piece's unrolled map (:mod:`segparam.unfold`) and its quality, lower
    corner at 0, if the piece is developable, unrolls consistently and bijectively; else None
    (the solver maps it). ``tube``: the piece is a tube cut open, developable even without
    inner vertices (``developable(..., strips=True)``)."""
    vert_chart = np.zeros(len(V), dtype=np.int64)
    if not developable(V, F, vert_chart, 1, strips=tube, euler=1)[0]:
        return None
    uv, q, kept = _unroll_checked(V, F, vert_chart, 1)
    return (uv, quality_records(q)[0]) if kept[0] else None


def _unroll_checked(
    V: np.ndarray, F: np.ndarray, vert_chart: np.ndarray, n: int
) -> tuple[np.ndarray, dict, np.ndarray]:
    """Every chart of a disjoint union unrolled (:func:`segparam.unfold.unroll_charts`), lower
    corners at 0, and measured (``charts_quality``): (uv, quality, kept), kept where a chart
    unrolled consistently (its sides within `EDGE_TOL`) and bijectively. The maps of the
    others are not maps (0 where a vertex was not reached)."""
    uv, error = unroll_charts(V, F, vert_chart, n)
    unrolled = error <= EDGE_TOL
    uv[~unrolled[vert_chart]] = 0.0  # NaN where a chart was not reached
    uv -= np.minimum.reduceat(uv, np.searchsorted(vert_chart, np.arange(n)))[vert_chart]
    q = charts_quality(V, F, uv, vert_chart, n)
    return uv, q, unrolled & q["bijective"]


def _solved(V: np.ndarray, F: np.ndarray, n_faces: int, cfg: SplitConfig, seed: int):
    """The solver's map of one piece, with the stage's settings."""
    return parameterize_chart(
        V, F, method=cfg.method, tangent=cfg.tangent, seed=seed, refine=cfg.refine,
        angle_weight=cfg.angle_weight, slim_below=_stretch_limit(n_faces, cfg),
    )  # fmt: skip


def _kept(result, n_faces: int, cfg: SplitConfig) -> bool:
    """Whether a solver's map is kept: bijective and within the targets."""
    q = result.quality
    return bool(result.bijective) and bool(
        _within_targets(q.angle_distortion, q.l2_stretch, n_faces, cfg)
    )


def _tube_cut(V: np.ndarray, F: np.ndarray) -> np.ndarray | None:
    """The cut that opens a tube of two loops (:func:`segparam.mesh.annulus_cut`), or None if
    it has not two loops or would open into a strip longer than ``TUBE_MAX_ASPECT`` times its
    width (its loops' mean length over the cut's)."""
    B = boundary_edges(F)
    pieces = boundary_pieces(B) if len(B) else None
    cut = annulus_cut(V, F, boundary=(B, pieces))
    if len(cut) == 0:
        return None
    _, idx, n_loops, loop = pieces
    length = np.linalg.norm(V[B[:, 0]] - V[B[:, 1]], axis=1)
    around = np.bincount(loop[idx[:, 0]], weights=length, minlength=n_loops).mean()
    across = np.linalg.norm(V[cut[:, 0]] - V[cut[:, 1]], axis=1).sum()
    return cut if around <= TUBE_MAX_ASPECT * across else None


def _opened(
    V: np.ndarray,
    F: np.ndarray,
    faces: np.ndarray,
    vertices: np.ndarray,
    src: int,
    depth: int,
    cfg: SplitConfig,
    seed: int,
    status: dict | None,
) -> Chart | None:
    """A tube piece (:func:`_tubes`) cut open along the shortest edge path from one of its
    two boundary loops to the other (:func:`segparam.mesh.annulus_cut`) and solved as the disk
    it then is; None if it has not two loops or that map is not kept (the caller splits it).
    One cut is the whole answer for a developable tube (the wall of a drilled hole, a pipe, a
    cone's side: one chart that unrolls without stretch), where a bisection gives two charts
    and two cuts.

    ``V, F`` are the piece's own vertices and faces, ``vertices`` their indices in the chart;
    the chart returned has a copy of each vertex on the cut for either side
    (``Chart.vertices`` repeats them)."""
    cut = _tube_cut(V, F)
    if cut is None:
        return None
    F_cut, copy_of = cut_along(F, cut)
    unrolled = _unrolled(V[copy_of], F_cut, tube=True)
    if unrolled is not None:
        if status is not None and "bijective" not in status:
            status["bijective"] = True
        log.debug("chart %d depth %d: cut open and unrolled", src, depth)
        return Chart(faces, vertices[copy_of], F_cut, *unrolled, src, depth, "developable")
    return _cut_solved(V, F_cut, copy_of, faces, vertices, src, depth, cfg, seed, status)


def _cut_solved(
    V: np.ndarray, F_cut: np.ndarray, copy_of: np.ndarray, faces: np.ndarray,
    vertices: np.ndarray, src: int, depth: int, cfg: SplitConfig, seed: int,
    status: dict | None = None,
) -> Chart | None:  # fmt: skip
    """A piece cut open (a tube, :func:`_opened`, or along a slit, :func:`_slit_ready`) solved
    alone: ``V`` its vertices' positions, ``F_cut`` its faces on their copies ``copy_of``,
    ``faces`` and ``vertices`` its faces and vertices in the chart. Its chart if the map is
    kept, else None (the caller splits it); ``status`` as :func:`_try_piece`'s."""
    try:
        result = _solved(V[copy_of], F_cut, len(faces), cfg, seed)
    except InvalidMeshError as exc:  # e.g. too thin for the solver's neighbourhoods: split it
        log.debug("chart %d depth %d, cut open: %s", src, depth, exc)
        return None
    if status is not None and "bijective" not in status:
        status["bijective"] = bool(result.bijective)
    if not _kept(result, len(faces), cfg):
        return None
    log.debug("chart %d depth %d: cut open into one chart", src, depth)
    return Chart(
        faces, vertices[copy_of], F_cut, result.uv, result.quality, src, depth, result.method
    )


def _slit_ready(
    V: np.ndarray, F: np.ndarray, faces: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """A candidate for a slit (:func:`_slit_candidates`; ``faces`` of the chart ``V, F``) cut
    along one (:func:`segparam.mesh.slit_cut`) when it is a disk: ``(vertices, F_cut,
    copy_of)``, the piece's vertices in the chart and its faces on their copies (the slit's
    vertices come twice: ``vertices[copy_of]``), else None."""
    vertices, local_F = submesh(F, faces)
    return _slit_cut(V, vertices, local_F) if is_disk(local_F) else None


def _slit_cut(
    V: np.ndarray, vertices: np.ndarray, local_F: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """:func:`_slit_ready` of a disk given as its chart's ``vertices`` and its ``local_F``."""
    cut = slit_cut(V[vertices], local_F)
    if len(cut) == 0:
        return None
    F_cut, copy_of = cut_along(local_F, cut)
    return vertices, F_cut, copy_of


def _slit_candidates(pieces: list[tuple], cfg: SplitConfig) -> np.ndarray:
    """Per ``(V, F, faces, src, depth)`` in ``pieces`` (a failed piece, ``faces`` of the chart
    ``V, F``), whether it may get a slit: deep enough (``SLIT_MIN_DEPTH``, up to
    ``max_depth``), large enough for the stretch target, and holding ``SLIT_MIN_CURVATURE``
    radians or more inside, mostly of one sign (``SLIT_ONE_SIGN``). For all pieces at once: the
    inner curvature of each piece from one union of their charts (a chart's vertices outside
    the piece hold no defect, so each sum is the piece's own, bit for bit). The split rounds
    hand over tens of failed pieces a round (the 2k brains): one by one, the test cost 0.1-0.3
    ms a piece; at once, the cow and the 2k brains build 1-2% faster (the same atlases)."""
    gate = np.array(
        [SLIT_MIN_DEPTH <= depth <= cfg.max_depth and len(faces) >= STRETCH_MIN_FACES
         for _, _, faces, _, depth in pieces], dtype=bool,
    )  # fmt: skip
    take = np.flatnonzero(gate)
    if len(take) == 0:
        return gate
    n_v = np.array([len(pieces[k][0]) for k in take])
    v_off = np.r_[0, np.cumsum(n_v)[:-1]]
    V = np.concatenate([pieces[k][0] for k in take])
    F = np.concatenate(
        [pieces[k][1][pieces[k][2]] + v_off[j] for j, k in enumerate(take)]
    )  # loop over the gated pieces: their faces in the union
    net, absolute = inner_curvature(V, F, np.repeat(np.arange(len(take)), n_v), len(take))
    gate[take] = net >= np.maximum(SLIT_MIN_CURVATURE, SLIT_ONE_SIGN * absolute)
    return gate


def _slit_open(
    V: np.ndarray, F: np.ndarray, faces: np.ndarray, src: int, depth: int, cfg: SplitConfig,
    seed: int,
) -> Chart | None:  # fmt: skip
    """A failed piece cut along a slit and solved alone, if it is a candidate
    (:func:`_slit_candidates`, :func:`_slit_ready`): its chart if the map is kept, else None
    (the caller bisects the piece)."""
    if not _slit_candidates([(V, F, faces, src, depth)], cfg)[0]:
        return None
    ready = _slit_ready(V, F, faces)
    return None if ready is None else _slit_solved(V, ready, faces, src, depth, cfg, seed)


def _slit_solved(
    V: np.ndarray, ready: tuple, faces: np.ndarray, src: int, depth: int, cfg: SplitConfig,
    seed: int,
) -> Chart | None:  # fmt: skip
    """A piece :func:`_slit_ready` cut open (``ready``; ``V`` its chart's vertices) solved alone
    (:func:`_cut_solved`)."""
    vertices, F_cut, copy_of = ready
    return _cut_solved(V[vertices], F_cut, copy_of, faces, vertices, src, depth, cfg, seed)


def _slit_charts(
    pieces: list[tuple], cfg: SplitConfig, seed: int, helpers: Helpers | None
) -> list[Chart | None]:
    """:func:`_slit_open` of every ``(V, F, faces, src, depth)`` in ``pieces`` (a chart's
    vertices and faces, the piece's faces in it): the small slit pieces (at most
    ``BATCH_MAX_VERTICES`` vertices) solved together (:func:`_solve_batch`, as
    :func:`_bulk_charts` solves the tubes it cuts open), the others alone."""
    out: list[Chart | None] = [None] * len(pieces)
    batch = []
    cand = np.flatnonzero(_slit_candidates(pieces, cfg))
    subs = [submesh(pieces[k][1], pieces[k][2]) for k in cand]  # loop over the candidates
    # which are disks, all at once (is_disk one by one cost 0.75 ms a piece; disk_labels gives
    # each label its own vertices, so the pieces' local faces need no offsets)
    nf = np.array([len(local_F) for _, local_F in subs], dtype=np.int64)
    disks = disk_labels(
        np.concatenate([local_F for _, local_F in subs]) if subs else np.zeros((0, 3), np.int64),
        np.repeat(np.arange(len(subs)), nf), len(subs),
    )  # fmt: skip
    for k, (vertices, local_F), disk in zip(cand.tolist(), subs, disks, strict=True):
        if not disk:
            continue
        V, F, faces, src, depth = pieces[k]
        ready = _slit_cut(V, vertices, local_F)
        if ready is None:
            continue
        _, _, copy_of = ready  # the piece's vertices, the slit's twice
        if len(copy_of) <= min(BATCH_MAX_VERTICES, DENSE_LIMIT):
            batch.append((k, ready))
        else:
            out[k] = _slit_solved(V, ready, faces, src, depth, cfg, seed)
    if not batch:
        return out
    Vs = [pieces[k][0][vertices[copy_of]] for k, (vertices, _, copy_of) in batch]
    nv = np.array([len(v) for v in Vs])
    vstart = np.r_[0, np.cumsum(nv)[:-1]]
    Fs = np.concatenate([F_cut + vstart[j] for j, (_, (_, F_cut, _)) in enumerate(batch)])
    n_faces = np.array([len(pieces[k][2]) for k, _ in batch])
    try:
        maps = _solve_batch(
            np.concatenate(Vs), Fs, np.repeat(np.arange(len(batch)), nv),
            _stretch_limit(n_faces, cfg), cfg, helpers,
        )  # fmt: skip
    except (InvalidMeshError, np.linalg.LinAlgError) as exc:  # not expected: one by one
        log.debug("batched slits failed (%s); solving %d one by one", exc, len(batch))
        for k, ready in batch:
            V, _, faces, src, depth = pieces[k]
            out[k] = _slit_solved(V, ready, faces, src, depth, cfg, seed)
        return out
    q = maps.quality
    ok = q["bijective"] & _within_targets(q["angle_distortion"], q["l2_stretch"], n_faces, cfg)
    for j, (k, (vertices, F_cut, copy_of)) in enumerate(batch):  # loop over the slit pieces
        if ok[j]:
            _, _, faces, src, depth = pieces[k]
            uv = maps.uv[vstart[j] : vstart[j] + nv[j]]
            out[k] = Chart(faces, vertices[copy_of], F_cut, uv, quality_records(q, [j])[0],
                           src, depth, "hessian")  # fmt: skip
    return out


def chart_face_cover(charts: tuple[Chart, ...], m: int) -> np.ndarray:
    """How many charts hold each face (1 everywhere for a valid chart set)."""
    if not charts:
        return np.zeros(m, dtype=np.int64)
    return np.bincount(np.concatenate([c.faces for c in charts]), minlength=m)
