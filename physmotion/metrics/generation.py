"""Text-to-motion generation metrics of the HumanML3D protocol (Guo et al. 2022, "Generating Diverse and
Natural 3D Human Motions from Text"), computed on embeddings from a text-motion evaluator.

The protocol embeds every caption and motion of the test split with Guo's contrastive evaluator, then:

- **R-Precision (top-1/2/3)** and **MM-Dist** (the "matching score"): the test pairs are taken in batches of
  32; in each, a caption's own motion should be among its nearest motions (:func:`r_precision`).
- **FID**: Frechet distance between Gaussians fitted to real and generated motion embeddings (:func:`fid`).
- **Diversity**: mean distance between 300 random pairs of generated motions (:func:`diversity`).
- **MultiModality**: mean distance between motions generated for the same caption (:func:`multimodality`).
- Each is repeated over several generation runs (20 in MDM) and reported as mean and 95% confidence
  half-width (:func:`confidence_interval`).

This module computes the numbers from given embeddings (numpy arrays); it does not embed anything.

Sources followed (code read, not copied): EricGuo5513/text-to-motion ``utils/metrics.py`` as vendored in
GuyTevet/motion-diffusion-model ``data_loaders/humanml/utils/metrics.py`` (``euclidean_distance_matrix``,
``calculate_top_k``, ``calculate_activation_statistics``, ``calculate_frechet_distance`` (itself from
pytorch-fid), ``calculate_diversity``, ``calculate_multimodality``), and MDM's ``eval/eval_humanml.py``
(``evaluate_matching_score``, ``get_metric_statistics``). Deviations are written where they occur.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np
from scipy import linalg

from physmotion.errors import ShapeError


class _InputError(ShapeError, ValueError):
    """Bad input: a ``ValueError`` as the metrics promise, and a :class:`ShapeError` so the CLI prints it."""


def _embeddings(name: str, x: object, ndim: int, min_rows: int = 1) -> np.ndarray:
    """``x`` as a finite float64 array with ``ndim`` dimensions and at least ``min_rows`` rows."""
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise _InputError(f"{name} must be a numeric array") from None
    if arr.ndim != ndim:
        raise _InputError(f"{name} must have {ndim} dimensions, got shape {arr.shape}")
    if arr.shape[0] < min_rows or 0 in arr.shape:
        raise _InputError(f"{name} needs at least {min_rows} rows and non-empty dimensions, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise _InputError(f"{name} contains NaN or infinite values")
    return arr


def _positive_int(name: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise _InputError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def embedding_stats(emb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean (D,) and sample covariance (D, D) of embeddings ``emb`` (N, D), N >= 2.

    As Guo's ``calculate_activation_statistics``: ``np.cov(rowvar=False)``, i.e. normalised by N - 1.
    """
    emb = _embeddings("emb", emb, 2, min_rows=2)  # np.cov of one row is NaN
    return emb.mean(axis=0), np.atleast_2d(np.cov(emb, rowvar=False))


def frechet_distance(mu1: np.ndarray, sigma1: np.ndarray, mu2: np.ndarray, sigma2: np.ndarray,
                     eps: float = 1e-6) -> float:  # fmt: skip
    """Frechet distance between N(mu1, sigma1) and N(mu2, sigma2): means (D,), covariances (D, D).

    ``||mu1 - mu2||^2 + tr(sigma1) + tr(sigma2) - 2 tr(sqrtm(sigma1 @ sigma2))``, as pytorch-fid and Guo's
    ``calculate_frechet_distance``: if the square root of the (possibly singular) product is not finite,
    ``eps`` is added to both diagonals; a negligible imaginary part from rounding is dropped, a large one
    (diagonal beyond 1e-3) raises ValueError. Like the reference the result is not clipped at 0, so a
    set against itself can give a tiny negative number.
    """
    mu1 = _embeddings("mu1", np.atleast_1d(mu1), 1)
    mu2 = _embeddings("mu2", np.atleast_1d(mu2), 1)
    sigma1 = _embeddings("sigma1", np.atleast_2d(sigma1), 2)
    sigma2 = _embeddings("sigma2", np.atleast_2d(sigma2), 2)
    d = mu1.shape[0]
    if mu2.shape != (d,) or sigma1.shape != (d, d) or sigma2.shape != (d, d):
        raise _InputError(
            f"means must be (D,) and covariances (D, D) with one D, got {mu1.shape}, {sigma1.shape}, "
            f"{mu2.shape}, {sigma2.shape}"
        )
    diff = mu1 - mu2
    # Covariances of fewer samples than dimensions are singular: scipy warns, and the finiteness check
    # below is the reference's answer to it (it too silences the warning, via disp=False).
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", linalg.LinAlgWarning)
        covmean = linalg.sqrtm(sigma1 @ sigma2)
    if not np.isfinite(covmean).all():
        offset = np.eye(d) * eps
        covmean = linalg.sqrtm((sigma1 + offset) @ (sigma2 + offset))
    if np.iscomplexobj(covmean):
        if not np.allclose(np.diagonal(covmean).imag, 0, atol=1e-3):
            raise _InputError(f"sqrtm(sigma1 @ sigma2) has a large imaginary component "
                              f"{np.max(np.abs(covmean.imag)):.3g}: are the covariances PSD?")  # fmt: skip
        covmean = covmean.real
    return float(diff @ diff + np.trace(sigma1) + np.trace(sigma2) - 2.0 * np.trace(covmean))


def fid(real: np.ndarray, generated: np.ndarray) -> float:
    """FID between embeddings of real motions ``real`` (N, D) and generated ones ``generated`` (M, D).

    N, M >= 2. Real statistics go first, as in MDM's ``evaluate_fid`` (the distance is symmetric anyway).
    """
    real = _embeddings("real", real, 2, min_rows=2)
    generated = _embeddings("generated", generated, 2, min_rows=2)
    if real.shape[1] != generated.shape[1]:
        raise _InputError(f"real and generated must share D, got {real.shape} and {generated.shape}")
    return frechet_distance(*embedding_stats(real), *embedding_stats(generated))


def r_precision(text_emb: np.ndarray, motion_emb: np.ndarray, top_k: int = 3,
                batch_size: int = 32) -> tuple[np.ndarray, float]:  # fmt: skip
    """R-Precision and MM-Dist of paired text (N, D) and motion (N, D) embeddings; row i of each is a pair.

    Guo's protocol (MDM ``evaluate_matching_score``): the pairs are cut into consecutive batches of
    ``batch_size`` (32 in the protocol: the value changes the metric, since each text competes with the
    other motions of its batch), an incomplete last batch dropped as their ``DataLoader(drop_last=True)``
    does. In each batch every text ranks the batch's motions by Euclidean distance; a stable sort breaks
    ties by index (the reference's default quicksort leaves them unspecified).

    Returns ``(accuracy, mm_dist)``: ``accuracy`` (top_k,) is cumulative, ``accuracy[k - 1]`` the fraction
    of texts whose own motion is among their k nearest; ``mm_dist`` the mean distance between each text
    and its own motion. Both average over all rows of the full batches.
    """
    text_emb = _embeddings("text_emb", text_emb, 2)
    motion_emb = _embeddings("motion_emb", motion_emb, 2)
    if text_emb.shape != motion_emb.shape:
        raise _InputError(f"text_emb and motion_emb must share a shape (N, D), got {text_emb.shape} "
                          f"and {motion_emb.shape}")  # fmt: skip
    top_k = _positive_int("top_k", top_k)
    batch_size = _positive_int("batch_size", batch_size)
    n = text_emb.shape[0]
    if n < batch_size:
        raise _InputError(f"r_precision needs at least batch_size={batch_size} pairs for one full batch, "
                          f"got {n}")  # fmt: skip
    if top_k > batch_size:
        raise _InputError(f"top_k must not exceed batch_size={batch_size}, got {top_k}")

    used = (n // batch_size) * batch_size
    hits = np.zeros(top_k, dtype=np.int64)
    diagonal_sum = 0.0
    own = np.arange(batch_size)
    # One batch at a time: the (B, B, D) differences of all batches at once would be large.
    for start in range(0, used, batch_size):
        t = text_emb[start : start + batch_size]
        m = motion_emb[start : start + batch_size]
        # Differences rather than Guo's |a|^2 - 2ab + |b|^2 expansion: no negative rounding under the sqrt.
        dist = np.linalg.norm(t[:, None, :] - m[None, :, :], axis=-1)  # (B, B): text i, motion j
        order = np.argsort(dist, axis=1, kind="stable")
        rank = np.argmax(order == own[:, None], axis=1)  # position of text i's own motion in its ranking
        hits += (rank[:, None] < np.arange(1, top_k + 1)[None, :]).sum(axis=0)
        diagonal_sum += float(np.trace(dist))
    return hits / used, diagonal_sum / used


def diversity(emb: np.ndarray, times: int = 300, seed: int = 0) -> float:
    """Diversity of generated motion embeddings ``emb`` (N, D), N >= 2.

    As Guo's ``calculate_diversity``: two index sets of ``times`` draws without replacement, the mean
    Euclidean distance of the ``times`` pairs. Guo requires N > times (300 out of the full test split);
    here ``times`` is clamped to N so small splits still work, in which case both sets are permutations
    and a pair can be a motion with itself. Seeded: ``np.random.default_rng(seed)``, first set then second.
    """
    emb = _embeddings("emb", emb, 2, min_rows=2)
    times = min(_positive_int("times", times), emb.shape[0])
    rng = np.random.default_rng(seed)
    first = rng.choice(emb.shape[0], times, replace=False)
    second = rng.choice(emb.shape[0], times, replace=False)
    return float(np.linalg.norm(emb[first] - emb[second], axis=1).mean())


def multimodality(emb: np.ndarray, times: int = 10, seed: int = 0) -> float:
    """MultiModality of embeddings ``emb`` (N, K, D): K generated motions for each of N texts, K >= 2.

    As Guo's ``calculate_multimodality``: two index sets of ``times`` draws from the K generations without
    replacement, drawn once and shared by all texts as the reference does; the mean Euclidean distance of
    the N * times pairs (equal to the mean over texts of each text's mean). ``times`` is clamped to K
    (Guo requires K > times: 10 out of 30 in the protocol).
    """
    emb = _embeddings("emb", emb, 3)
    k = emb.shape[1]
    if k < 2:
        raise _InputError(f"multimodality needs at least 2 generations per text, got K = {k}")
    times = min(_positive_int("times", times), k)
    rng = np.random.default_rng(seed)
    first = rng.choice(k, times, replace=False)
    second = rng.choice(k, times, replace=False)
    return float(np.linalg.norm(emb[:, first] - emb[:, second], axis=2).mean())


def multimodality_per_text(emb: np.ndarray) -> np.ndarray:
    """Each text's mean distance over all K(K-1)/2 distinct pairs of its generations: (N, K, D) -> (N,).

    The exact expectation of Guo's random pair when K is small (our evaluation's K is the number of
    repeats, a handful): a draw of ``times`` pairs from so few generations would pair motions with
    themselves and bias MultiModality low. Averaged over texts it is MultiModality, and its spread over
    texts gives a confidence interval.
    """
    emb = _embeddings("emb", emb, 3)
    k = emb.shape[1]
    if k < 2:
        raise _InputError(f"multimodality needs at least 2 generations per text, got K = {k}")
    d = np.linalg.norm(emb[:, :, None] - emb[:, None, :], axis=-1)
    iu = np.triu_indices(k, k=1)
    return d[:, iu[0], iu[1]].mean(axis=1)


def confidence_interval(values: Sequence[float]) -> tuple[float, float]:
    """Mean and 95% confidence half-width ``1.96 * std / sqrt(n)`` of one metric over n runs.

    As MDM's ``get_metric_statistics``: population std (ddof=0), so one run gives a half-width of 0.
    """
    arr = _embeddings("values", values, 1)
    half = 1.96 * float(arr.std()) / math.sqrt(arr.shape[0])
    return float(arr.mean()), half
