"""The paper's comparison as a regression suite (section 4: the segmented Brain dataset).

On synthetic parcels cut like atlas regions from the realistic default hemisphere (as folded as
fsaverage5's pial surface: ``segparam.synthetic``), in both mesh kinds (well-shaped uniform
triangles, and icosahedral template connectivity like FreeSurfer's), the single-pass bijective
rate of the raw eigenmaps must keep the paper's ordering (averaged-normal tangents beat PCA
tangents, which beat classic HLLE), and the default solver (Hessian map + ARAP) must stay near
all charts bijective. The parcels are used as cut, not remeshed, like real atlas parcels. The
floors are set from measurements (BENCHMARKS.md, ``benchmarks/bench_solver.py --parcel-set
cortex`` / ``cortex-ico``) a few charts below what was measured, so a regression fails them.

A fast 12-parcel set per mesh kind runs by default; the 89-parcel sets run with ``pytest -m full``.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from segparam.parameterize import parameterize_chart
from segparam.synthetic import brain_like_parcels


@functools.lru_cache(maxsize=4)
def parcels(n: int, connectivity: str) -> tuple:
    """``n`` parcels of 380-560 faces (mean 460, like 89 parcels of fsaverage5's pial surface)."""
    return tuple(
        brain_like_parcels(
            n, mean_faces=460, min_faces=380, max_faces=560, connectivity=connectivity, seed=0
        )
    )


def rates(charts, **options) -> tuple[int, float]:
    results = [parameterize_chart(V, F, **options) for V, F in charts]
    ok = sum(r.bijective for r in results)
    return ok, float(np.median([r.quality.angle_distortion for r in results]))


def check_table(charts, floors, *, with_pca=False):
    n = len(charts)
    normals, _ = rates(charts, refine="none")
    classic, _ = rates(charts, method="classic-hlle", refine="none")
    refined, median_ad = rates(charts)
    assert normals > classic  # the paper's ordering
    if with_pca:
        pca, _ = rates(charts, tangent="pca", refine="none")
        assert normals > pca > classic  # averaged normals beat PCA tangents (paper, section 3.1)
    assert normals >= floors["normals"] * n
    assert refined >= floors["refined"] * n
    assert median_ad <= floors["median_angle_distortion"]


FAST = {
    # measured (issue 16, tangent planes turned where they fold a triangle + the eigenvector
    # selection): normals 11/12, PCA 1, classic 0, refined 12/12, median s1/s2 1.113 (before:
    # 9, 0, 0, 12, 1.114; before the smoothed normals and the fallback pairs: 7, 0, 0, 12, 1.109)
    "uniform": {"normals": 0.75, "refined": 0.9, "median_angle_distortion": 1.15},
    # measured: normals 12/12, PCA 2, classic 0, refined 12/12, median s1/s2 1.109
    # (before: 11, 2, 0, 12, 1.109; earlier 6, 2, 0, 12, 1.119)
    "icosahedral": {"normals": 0.8, "refined": 0.9, "median_angle_distortion": 1.15},
}
FULL = {
    # measured: normals 86/89, PCA 16, classic 8, refined 89/89, median s1/s2 1.090
    # (fsaverage5's real pial parcels: 87, 46, 10, 89/89, 1.088); before the turned planes and
    # the eigenvector selection: 82, 15, 8, 89/89, 1.091 (fsaverage5 81, 41, 10, 89/89, 1.089);
    # before issue 16's solver changes: 53, 15, 8, 85/89, 1.089
    "uniform": {"normals": 0.93, "refined": 0.97, "median_angle_distortion": 1.12},
    # measured: normals 86/89, PCA 26, classic 17, refined 89/89, median s1/s2 1.088
    # (before: 80, 24, 17, 89/89, 1.090; earlier 55, 24, 17, 88/89, 1.088)
    "icosahedral": {"normals": 0.93, "refined": 0.97, "median_angle_distortion": 1.12},
}


@pytest.mark.parametrize("connectivity", ["uniform", "icosahedral"])
def test_paper_table_fast_subset(connectivity):
    check_table(parcels(12, connectivity), FAST[connectivity])


@pytest.mark.full
@pytest.mark.parametrize("connectivity", ["uniform", "icosahedral"])
def test_paper_table_full(connectivity):
    check_table(parcels(89, connectivity), FULL[connectivity], with_pca=True)
