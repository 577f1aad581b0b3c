"""HumanML3D generation metrics (R-Precision, MM-Dist, FID, Diversity, MultiModality) against hand values."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from physmotion.errors import ShapeError
from physmotion.metrics.generation import (
    confidence_interval,
    diversity,
    embedding_stats,
    fid,
    frechet_distance,
    multimodality,
    r_precision,
)

# ------------------------------------------------------------------------------------------------
# Statistics and FID


def test_embedding_stats_of_a_square() -> None:
    mu, cov = embedding_stats(np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 2.0], [2.0, 2.0]]))
    np.testing.assert_allclose(mu, [1.0, 1.0])
    np.testing.assert_allclose(cov, np.diag([4 / 3, 4 / 3]), atol=1e-12)  # 4 * 1^2 / (N - 1)


def test_frechet_distance_of_diagonal_gaussians() -> None:
    # per dimension (mu1 - mu2)^2 + s1 + s2 - 2 sqrt(s1 s2): (1 + 1 + 9 - 6) + (1 + 4 + 16 - 16) = 10
    value = frechet_distance(np.zeros(2), np.diag([1.0, 4.0]), np.ones(2), np.diag([9.0, 16.0]))
    assert value == pytest.approx(10.0, rel=1e-9)


def test_frechet_distance_of_equal_full_covariances_is_the_mean_gap() -> None:
    cov = np.array([[2.0, 1.0], [1.0, 2.0]])  # sqrtm(cov @ cov) = cov, so the traces cancel
    assert frechet_distance(np.zeros(2), cov, np.array([3.0, 4.0]), cov) == pytest.approx(25.0, rel=1e-9)


def test_frechet_distance_accepts_scalars_for_one_dimension() -> None:
    assert frechet_distance(1.0, 2.0, 8.0, 18.0) == pytest.approx(49 + 2 + 18 - 2 * 6, rel=1e-9)


def test_frechet_distance_of_a_singular_product() -> None:
    # sigma1 @ sigma2 = 0: sqrt of the product is 0 (or, after the eps offset, ~1e-3), so ~ 1 + 1
    value = frechet_distance(np.zeros(2), np.diag([1.0, 0.0]), np.zeros(2), np.diag([0.0, 1.0]))
    assert value == pytest.approx(2.0, abs=1e-2)


def test_frechet_distance_offsets_the_diagonals_when_sqrtm_fails(monkeypatch: pytest.MonkeyPatch) -> None:
    from scipy import linalg

    real_sqrtm, calls = linalg.sqrtm, []

    def failing_once(a: np.ndarray) -> np.ndarray:
        calls.append(a.copy())
        return np.full_like(a, np.nan) if len(calls) == 1 else real_sqrtm(a)

    monkeypatch.setattr(linalg, "sqrtm", failing_once)
    value = frechet_distance(np.zeros(1), np.array([[4.0]]), np.ones(1), np.array([[9.0]]), eps=0.5)
    assert len(calls) == 2
    np.testing.assert_allclose(calls[1], [[4.5 * 9.5]])  # (sigma1 + eps I) @ (sigma2 + eps I)
    assert value == pytest.approx(1 + 4 + 9 - 2 * math.sqrt(4.5 * 9.5), rel=1e-12)


def test_frechet_distance_rejects_a_large_imaginary_part() -> None:
    with pytest.raises(ValueError, match="imaginary"):
        frechet_distance(np.zeros(2), np.diag([1.0, -1.0]), np.zeros(2), np.eye(2))


def test_fid_of_a_set_against_itself_is_zero() -> None:
    emb = np.random.default_rng(0).normal(size=(50, 4))
    assert abs(fid(emb, emb)) < 1e-6


def test_fid_of_one_dimensional_sets() -> None:
    # real [0, 2]: mean 1, var 2; generated [5, 11]: mean 8, var 18 -> 49 + 2 + 18 - 2 * sqrt(36) = 57
    assert fid(np.array([[0.0], [2.0]]), np.array([[5.0], [11.0]])) == pytest.approx(57.0, rel=1e-6)


def _cross(a: float, b: float, centre: tuple[float, float]) -> np.ndarray:
    """(±a, 0), (0, ±b) around ``centre``: mean ``centre``, covariance diag(2a^2/3, 2b^2/3), no cross term"""
    return np.array([[a, 0.0], [-a, 0.0], [0.0, b], [0.0, -b]]) + np.asarray(centre)


def test_fid_of_diagonal_two_dimensional_sets() -> None:
    real = _cross(3.0, 6.0, (1.0, 2.0))  # covariance diag(6, 24)
    generated = _cross(6.0, 3.0, (4.0, -2.0))  # covariance diag(24, 6)
    # |(3, -4)|^2 + (6 + 24 - 2 * 12) + (24 + 6 - 2 * 12) = 25 + 6 + 6
    assert fid(real, generated) == pytest.approx(37.0, rel=1e-6)
    assert fid(generated, real) == pytest.approx(37.0, rel=1e-6)


# ------------------------------------------------------------------------------------------------
# R-Precision and MM-Dist


def _ranked_batch() -> tuple[np.ndarray, np.ndarray]:
    """4 pairs where text i's own motion is its (i + 1)-th nearest.

    Motions are the unit vectors e_j; every text is t = (0.4, 0.3, 0.2, 0.1), and
    |t - e_j|^2 = |t|^2 + 1 - 2 t_j ranks the motions 0, 1, 2, 3.
    """
    motions = np.eye(4)
    texts = np.tile([0.4, 0.3, 0.2, 0.1], (4, 1))
    return texts, motions


_RANKED_DISTANCES = np.sqrt(1.3 - 2 * np.array([0.4, 0.3, 0.2, 0.1]))  # text i to its own motion i


def test_r_precision_with_known_ranks() -> None:
    texts, motions = _ranked_batch()
    acc, mm_dist = r_precision(texts, motions, top_k=3, batch_size=4)
    assert acc.shape == (3,)
    np.testing.assert_allclose(acc, [1 / 4, 2 / 4, 3 / 4], atol=1e-12)
    assert mm_dist == pytest.approx(_RANKED_DISTANCES.mean(), rel=1e-12)
    acc4, _ = r_precision(texts, motions, top_k=4, batch_size=4)
    assert acc4[-1] == 1.0


def test_r_precision_drops_an_incomplete_last_batch() -> None:
    texts, motions = _ranked_batch()
    # Three more pairs, far apart and each matched perfectly: they would change both numbers if used.
    extra = np.array([[100.0, 0, 0, 0], [0, 200.0, 0, 0], [0, 0, 300.0, 0]])
    acc, mm_dist = r_precision(np.vstack([texts, extra]), np.vstack([motions, extra + 1.0]), batch_size=4)
    np.testing.assert_allclose(acc, [1 / 4, 2 / 4, 3 / 4], atol=1e-12)
    assert mm_dist == pytest.approx(_RANKED_DISTANCES.mean(), rel=1e-12)


def test_r_precision_averages_over_full_batches_and_ranks_only_within_a_batch() -> None:
    texts, motions = _ranked_batch()
    # Second batch: each text sits exactly on its own motion (rank 0, distance 0). Its motions are also
    # close to the first batch's texts, which must not see them.
    second = np.tile([0.4, 0.3, 0.2, 0.1], (4, 1)) + np.diag([0.01, 0.02, 0.03, 0.04])
    acc, mm_dist = r_precision(np.vstack([texts, second]), np.vstack([motions, second]), batch_size=4)
    np.testing.assert_allclose(acc, [(1 + 4) / 8, (2 + 4) / 8, (3 + 4) / 8], atol=1e-12)
    assert mm_dist == pytest.approx(_RANKED_DISTANCES.sum() / 8, rel=1e-12)


def test_r_precision_breaks_ties_by_index() -> None:
    texts = np.zeros((2, 2))  # both texts equidistant from both motions: the stable order is [0, 1]
    motions = np.eye(2)
    acc, mm_dist = r_precision(texts, motions, top_k=2, batch_size=2)
    np.testing.assert_allclose(acc, [0.5, 1.0])
    assert mm_dist == pytest.approx(1.0)


def test_r_precision_rejects_too_few_pairs() -> None:
    texts, motions = _ranked_batch()
    with pytest.raises(ValueError, match="batch_size=32"):
        r_precision(texts, motions)


@pytest.mark.parametrize(
    ("texts", "motions", "kwargs", "match"),
    [
        (np.zeros((4, 3)), np.zeros((4, 2)), {}, "share a shape"),
        (np.zeros((4, 3)), np.zeros((5, 3)), {}, "share a shape"),
        (np.zeros(4), np.zeros(4), {}, "2 dimensions"),
        (np.full((4, 2), np.nan), np.zeros((4, 2)), {}, "NaN"),
        (np.zeros((4, 2)), np.full((4, 2), np.inf), {}, "NaN or infinite"),
        (np.zeros((4, 2)), np.zeros((4, 2)), {"top_k": 5}, "top_k"),
        (np.zeros((4, 2)), np.zeros((4, 2)), {"top_k": 0}, "top_k"),
        (np.zeros((4, 2)), np.zeros((4, 2)), {"batch_size": 0}, "batch_size"),
    ],
)
def test_r_precision_rejects_bad_input(
    texts: np.ndarray, motions: np.ndarray, kwargs: dict, match: str
) -> None:
    kwargs = {"top_k": 3, "batch_size": 4} | kwargs
    with pytest.raises(ValueError, match=match):
        r_precision(texts, motions, **kwargs)


# ------------------------------------------------------------------------------------------------
# Diversity and MultiModality


def test_diversity_of_equal_points_is_zero() -> None:
    assert diversity(np.ones((10, 3)), times=5) == 0.0


def test_diversity_of_collinear_points_from_the_same_draws() -> None:
    x = np.array([0.0, 1.0, 3.0, 6.0, 10.0])
    emb = np.stack([x, 2 * x], axis=1)  # on a line through 0: |emb_a - emb_b| = sqrt(5) |x_a - x_b|
    rng = np.random.default_rng(3)
    first, second = rng.choice(5, 5, replace=False), rng.choice(5, 5, replace=False)
    expected = math.sqrt(5) * np.abs(x[first] - x[second]).mean()
    assert diversity(emb, times=5, seed=3) == pytest.approx(expected, rel=1e-12)
    assert diversity(emb, times=300, seed=3) == pytest.approx(expected, rel=1e-12)  # clamped to N = 5


def test_diversity_of_two_clusters_counts_the_cross_pairs() -> None:
    # 1 point at 0 and 1 point at d: a pair is either within (0) or across (d), so times = 2 gives 0 or d.
    values = {diversity(np.array([[0.0], [7.0]]), times=2, seed=s) for s in range(20)}
    assert values == {0.0, 7.0}


def test_diversity_is_deterministic_per_seed() -> None:
    emb = np.random.default_rng(0).normal(size=(40, 8))
    assert diversity(emb, times=20, seed=5) == diversity(emb, times=20, seed=5)
    assert len({diversity(emb, times=20, seed=s) for s in range(5)}) > 1


@pytest.mark.parametrize(
    ("emb", "kwargs", "match"),
    [
        (np.zeros((1, 3)), {}, "at least 2 rows"),
        (np.zeros((4, 3, 2)), {}, "2 dimensions"),
        (np.array([[0.0], [np.nan]]), {}, "NaN"),
        (np.zeros((4, 3)), {"times": 0}, "times"),
    ],
)
def test_diversity_rejects_bad_input(emb: np.ndarray, kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        diversity(emb, **kwargs)


def test_multimodality_of_identical_generations_is_zero() -> None:
    emb = np.repeat(np.random.default_rng(0).normal(size=(5, 1, 4)), 6, axis=1)  # (5 texts, 6 copies, 4)
    assert multimodality(emb, times=3) == 0.0


def test_multimodality_from_the_same_draws() -> None:
    x = np.array([0.0, 1.0, 3.0, 6.0])  # generations of text n on a line at n + x * (n + 1)
    emb = np.stack([n + x * (n + 1) for n in range(3)])[..., None]  # (3, 4, 1)
    rng = np.random.default_rng(0)
    first, second = rng.choice(4, 4, replace=False), rng.choice(4, 4, replace=False)
    base = np.abs(x[first] - x[second]).mean()
    # One draw shared by the texts, text n's distances scaled by n + 1: mean scale 2.
    assert multimodality(emb, times=4, seed=0) == pytest.approx(2 * base, rel=1e-12)
    assert multimodality(emb, times=10, seed=0) == pytest.approx(2 * base, rel=1e-12)  # clamped to K = 4


def test_multimodality_averages_over_texts_regardless_of_the_draw() -> None:
    rng = np.random.default_rng(1)
    one = rng.normal(size=(1, 8, 5))
    # Text 2 is text 1 scaled by 3 and moved: whatever pairs are drawn, its distances are 3x text 1's.
    two = np.concatenate([one, 3 * one + 10.0])
    for seed in range(5):
        assert multimodality(two, times=4, seed=seed) == pytest.approx(
            2 * multimodality(one, times=4, seed=seed), rel=1e-12
        )


@pytest.mark.parametrize(
    ("emb", "kwargs", "match"),
    [
        (np.zeros((3, 1, 2)), {}, "K = 1"),
        (np.zeros((3, 2)), {}, "3 dimensions"),
        (np.full((2, 3, 2), np.inf), {}, "infinite"),
        (np.zeros((2, 3, 2)), {"times": -1}, "times"),
    ],
)
def test_multimodality_rejects_bad_input(emb: np.ndarray, kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        multimodality(emb, **kwargs)


# ------------------------------------------------------------------------------------------------
# Confidence interval and errors


def test_confidence_interval_by_hand() -> None:
    mean, half = confidence_interval([1.0, 2.0, 3.0, 4.0])
    assert mean == pytest.approx(2.5)
    assert half == pytest.approx(1.96 * math.sqrt(1.25) / 2)  # population std sqrt(1.25), n = 4


def test_confidence_interval_of_one_run() -> None:
    assert confidence_interval([0.42]) == (pytest.approx(0.42), 0.0)


@pytest.mark.parametrize("values", [[], [1.0, float("nan")], [[1.0, 2.0]], ["a"]])
def test_confidence_interval_rejects_bad_input(values: list) -> None:
    with pytest.raises(ValueError):
        confidence_interval(values)


@pytest.mark.parametrize(
    "call",
    [
        lambda: embedding_stats(np.zeros((1, 3))),
        lambda: embedding_stats(np.zeros(3)),
        lambda: fid(np.zeros((4, 3)), np.zeros((4, 2))),
        lambda: fid(np.zeros((4, 3)), np.full((4, 3), np.nan)),
        lambda: frechet_distance(np.zeros(2), np.eye(2), np.zeros(3), np.eye(3)),
        lambda: frechet_distance(np.zeros(2), np.eye(3), np.zeros(2), np.eye(2)),
        lambda: frechet_distance(np.zeros(2), np.eye(2), np.zeros(2), np.full((2, 2), np.inf)),
    ],
)
def test_stats_and_fid_reject_bad_input(call: Callable[[], object]) -> None:
    with pytest.raises(ValueError):
        call()


def test_errors_are_also_the_projects_shape_error() -> None:
    with pytest.raises(ShapeError, match="NaN"):
        fid(np.zeros((4, 3)), np.full((4, 3), np.nan))
