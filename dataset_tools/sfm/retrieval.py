"""Which photos to match, past a few dozen: each with the photos that look most alike.

Exhaustive matching tries every pair, n(n-1)/2 of them: 4560 for 96 photos, and on one
thread the matcher spends most of structure from motion on pairs that share nothing. A
vocabulary tree finds the pairs worth trying, but needs a vocabulary trained beforehand on
millions of images; here the scene's own SIFT descriptors make a small one (k-means on a
sample of them), every photo becomes one VLAD vector (its descriptors' residuals to their
nearest word, summed per word; Jegou et al. 2010, with RootSIFT descriptors and
intra-normalisation), and each photo is matched with the ``neighbours`` photos whose
vectors are the most alike (cosine similarity). The photos need no order.
"""

from __future__ import annotations

import numpy as np

WORDS = 64  # the size of the scene's vocabulary
SAMPLE = 20_000  # descriptors k-means runs on, taken evenly from every photo
PER_PHOTO = 3_000  # descriptors of a photo that make its vector, at most
ITERATIONS = 15  # of k-means


def root_sift(descriptors: np.ndarray) -> np.ndarray:
    """(K, D) float32 RootSIFT (Arandjelovic & Zisserman 2012) of (K, D) SIFT descriptors:
    L1-normalised, then the square root, which makes the Euclidean distance a Hellinger
    kernel."""
    x = descriptors.astype(np.float32)
    return np.sqrt(x / np.maximum(x.sum(1, keepdims=True), 1e-12))


def _nearest(x: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """(K,) index of the nearest of ``centres`` (W, D) to each row of ``x`` (K, D)."""
    return ((centres**2).sum(1)[None] - 2.0 * x @ centres.T).argmin(1)


def _spread(descriptors: list[np.ndarray], count: int, rng: np.random.Generator) -> list[np.ndarray]:
    """At most ``count`` descriptors of each photo, drawn without replacement."""
    return [d[rng.choice(len(d), min(count, len(d)), replace=False)] for d in descriptors]


def vocabulary(descriptors: list[np.ndarray], words: int = WORDS, seed: int = 0) -> np.ndarray:
    """A vocabulary for a scene: k-means (Lloyd's, from ``words`` descriptors drawn at random)
    on :data:`SAMPLE` RootSIFT descriptors drawn evenly from the photos.

    Args:
        descriptors: per photo, (K_i, D) SIFT descriptors.
        words: the number of centres; fewer when there are few descriptors.
        seed: of the draws.
    Returns:
        (W, D) float32 centres.
    """
    if not any(len(d) for d in descriptors):
        raise ValueError("no photo has a descriptor")
    rng = np.random.default_rng(seed)
    data = np.concatenate([root_sift(d) for d in _spread(descriptors, max(1, SAMPLE // len(descriptors)), rng)])
    centres = data[rng.choice(len(data), min(words, len(data)), replace=False)]
    for _ in range(ITERATIONS):
        owner = _nearest(data, centres)
        sums = np.zeros_like(centres)
        np.add.at(sums, owner, data)
        counts = np.bincount(owner, minlength=len(centres))
        used = counts > 0
        centres[used] = sums[used] / counts[used, None]
    return centres


def vlad(descriptors: list[np.ndarray], centres: np.ndarray, seed: int = 0) -> np.ndarray:
    """(n, W * D) float32 VLAD vectors of n photos (descriptors (K_i, D) each, at most
    :data:`PER_PHOTO` of them used) over ``centres`` (W, D): residuals summed per word,
    each word's sum L2-normalised (intra-normalisation), the whole L2-normalised."""
    rng = np.random.default_rng(seed)
    out = np.zeros((len(descriptors), centres.size), np.float32)
    for i, d in enumerate(_spread(descriptors, PER_PHOTO, rng)):
        if not len(d):
            continue
        x = root_sift(d)
        owner = _nearest(x, centres)
        sums = np.zeros_like(centres)
        np.add.at(sums, owner, x - centres[owner])
        sums /= np.maximum(np.linalg.norm(sums, axis=1, keepdims=True), 1e-12)
        out[i] = sums.ravel()
    return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)


def similar_pairs(vectors: np.ndarray, neighbours: int) -> list[tuple[int, int]]:
    """Pairs (i < j) of photos where j is among the ``neighbours`` photos most alike i, or i
    among those of j, by the cosine similarity of their ``vectors`` (n, F), each of unit length."""
    n = len(vectors)
    k = min(neighbours, n - 1)
    if k < 1:
        return []
    similarity = vectors @ vectors.T
    np.fill_diagonal(similarity, -np.inf)
    nearest = np.argsort(-similarity, axis=1, kind="stable")[:, :k]
    return sorted({(min(i, int(j)), max(i, int(j))) for i in range(n) for j in nearest[i]})
