"""The annealing budget of a handle-count comparison (simfab.design.study.iterations_per_handle_budget)
on a least-squares stand-in of profile matching with a closed-form optimum.

Stand-in: a force profile sampled at 39 distances (as profile2d_target.csv) is fitted by m
"handles" of 4 design variables each (a 2D handle: 2 translations, 2 scales), the variables being
the coefficients of nested orthonormal polynomial bases (span of 4 m Legendre polynomials, each
basis vector with unit RMS over the samples): the design spaces of 2, 4 and 8 handles are nested,
so the least-squares optimum RMS* (np.linalg.lstsq) falls with m, and since the basis is
orthonormal RMS(h)^2 = RMS*^2 + |h - h*|^2: the annealer's distance from the optimum is read off
its RMS. The target has a kink where contact starts (force 0 before), so no count fits it
exactly. The annealer (same moves as the design loop: one block per handle, seeded) starts from
h = 0 (RMS ~6.5 N)."""

import numpy as np

from simfab.design.anneal import AnnealConfig, anneal
from simfab.design.brief import DesignConfig
from simfab.design.study import iterations_per_handle_budget

N_SAMPLES = 39
S = np.linspace(-1.0, 1.0, N_SAMPLES)
U = np.clip((S + 0.8) / 1.75, 0.0, 1.0)
TARGET = -9.0 * np.sin(2.0 * np.pi * U)  # [N]; 0 before contact (U = 0), a kink at its onset
BASIS = np.linalg.qr(np.polynomial.legendre.legvander(S, 31))[0] * np.sqrt(N_SAMPLES)  # (39, 32), nested
VARS_PER_HANDLE = 4
SEEDS = range(7)


def fit(handles: int, iterations: int, seed: int) -> tuple[float, float]:
    """(annealed RMS, least-squares optimum RMS*) [N] of the stand-in with ``handles`` handles."""
    n = VARS_PER_HANDLE * handles
    B = BASIS[:, :n]
    h_star = np.linalg.lstsq(B, TARGET, rcond=None)[0]
    rms_star = float(np.sqrt(np.mean((B @ h_star - TARGET) ** 2)))

    def f(h, threshold=None):
        return float(np.mean((B @ h - TARGET) ** 2)), None  # mean squared error [N^2], as problem.evaluate

    blocks = np.repeat(np.arange(handles), VARS_PER_HANDLE)
    r = anneal(f, np.zeros(n), AnnealConfig(iterations=iterations, sigma0=np.ones(n), lower=np.full(n, -20.0),
                                             upper=np.full(n, 20.0), blocks=blocks, seed=seed))
    return float(np.sqrt(r.value)), rms_star


def gap(handles: int, iterations: int) -> float:
    """Median over seeds of the distance |h - h*| [N] the annealer stops at (RMS^2 = RMS*^2 + |h - h*|^2)."""
    out = [fit(handles, iterations, s) for s in SEEDS]
    return float(np.median([np.sqrt(max(r * r - r0 * r0, 0.0)) for r, r0 in out]))


def test_budget_per_handle_is_the_scene_budget_scaled_by_the_count():
    brief = DesignConfig(iterations=300, handles=4)  # profile2d's
    assert [iterations_per_handle_budget(brief, k) for k in (2, 4, 8)] == [150, 300, 600]
    assert iterations_per_handle_budget(DesignConfig(iterations=1, handles=4), 1) == 1


def test_optimum_falls_with_handle_count():
    rms_star = [fit(k, 1, 0)[1] for k in (2, 4, 8)]
    assert rms_star[0] > 2 * rms_star[1] > 4 * rms_star[2]


def test_one_budget_for_all_counts_leaves_the_largest_count_furthest_from_its_optimum():
    """With the same 300 iterations, 8 handles (32 variables) stop several times further from
    their optimum than 2 (8 variables); with the budget per handle (600 vs 150) the distances match
    within the spread of the seeds - the budget rule of a handle-count comparison."""
    fixed = {k: gap(k, 300) for k in (2, 8)}
    assert fixed[8] > 3.0 * fixed[2]
    brief = DesignConfig(iterations=300, handles=4)
    scaled = {k: gap(k, iterations_per_handle_budget(brief, k)) for k in (2, 8)}
    assert scaled[8] < 1.5 * scaled[2]
    assert scaled[8] < 0.4 * fixed[8]
