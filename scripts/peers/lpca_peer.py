"""Peer check for btfmrf's local PCA: the same algorithm in numpy (Gram-matrix PCA).

Local PCA of Kambhatla and Leen as used by Müller et al. (2003): K random rows as centres,
empty bases; then repeat: assign every row to the cluster with the smallest squared
reconstruction error, recompute each cluster's mean and its top-C principal directions
(eigenvectors of the cluster's n_k x n_k Gram matrix, numpy.linalg.eigh). A last assignment
gives the final error. float32 data and products, float64 eigen problems, like ours.

Usage: python lpca_peer.py DATA.npy [RUNS] [SEED]
Prints one JSON line: seconds (median of RUNS) and the final mean squared error per row.
"""

import json
import sys
import time

import numpy as np


def assign(x, norms, means, bases):
    """Cluster index, squared reconstruction error and weights of every row."""
    k, c, d = bases.shape
    m = np.concatenate([means, bases.reshape(k * c, d)], axis=0)
    p = x @ m.T  # n x K(C+1), float32 GEMM
    mm = np.einsum("kd,kd->k", means.astype(np.float64), means.astype(np.float64))
    me = np.einsum("kd,kcd->kc", means.astype(np.float64), bases.astype(np.float64))
    proj = p[:, k:].reshape(-1, k, c).astype(np.float64) - me[None]
    err = norms[:, None] - 2.0 * p[:, :k].astype(np.float64) + mm[None] - (proj**2).sum(-1)
    j = np.argmin(err, axis=1)
    rows = np.arange(x.shape[0])
    return j, np.maximum(err[rows, j], 0.0), proj[rows, j]


def gram_pca(y, c):
    """Top-c principal directions of the centred rows of y via the Gram matrix."""
    n, d = y.shape
    out = np.zeros((c, d), dtype=np.float32)
    if n == 0:
        return out
    if n <= d:
        g = (y @ y.T).astype(np.float64)
        w, u = np.linalg.eigh(g)
        order = np.argsort(w)[::-1][:c]
        for t, i in enumerate(order):
            if w[i] > 1e-12 * max(w.sum(), 1e-300):
                v = y.T @ u[:, i].astype(np.float32)
                out[t] = v / np.linalg.norm(v)
    else:
        cov = (y.T @ y).astype(np.float64)
        w, v = np.linalg.eigh(cov)
        order = np.argsort(w)[::-1][:c]
        out[: len(order)] = v[:, order].T.astype(np.float32)
    return out


def local_pca(data, k, c, iterations, seed):
    n, d = data.shape
    g = data.mean(axis=0, dtype=np.float64).astype(np.float32)
    x = data - g
    norms = np.einsum("nd,nd->n", x.astype(np.float64), x.astype(np.float64))
    rng = np.random.default_rng(seed)
    means = x[np.sort(rng.choice(n, size=k, replace=False))].copy()
    bases = np.zeros((k, c, d), dtype=np.float32)
    j, err, _ = assign(x, norms, means, bases)
    history = [float(err.mean())]
    for _ in range(iterations):
        for cl in range(k):
            members = np.flatnonzero(j == cl)
            if members.size == 0:
                continue
            y = x[members]
            mean = y.mean(axis=0, dtype=np.float64).astype(np.float32)
            means[cl] = mean
            bases[cl] = gram_pca(y - mean, c)
        j, err, _ = assign(x, norms, means, bases)
        history.append(float(err.mean()))
    return history, np.bincount(j, minlength=k)


def main():
    path = sys.argv[1]
    runs = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    seed = int(sys.argv[3]) if len(sys.argv) > 3 else 1
    data = np.load(path).astype(np.float32)
    times = []
    for _ in range(max(runs, 1)):
        t = time.perf_counter()
        history, sizes = local_pca(data, 32, 8, 10, seed)
        times.append(time.perf_counter() - t)
    times.sort()
    print(
        json.dumps(
            {
                "side": "numpy " + np.__version__,
                "n": data.shape[0],
                "d": data.shape[1],
                "clusters": 32,
                "components": 8,
                "iterations": 10,
                "seconds_median": times[len(times) // 2],
                "seconds_all": times,
                "mean_squared_error": history[-1],
                "error_history": history,
                "largest_cluster": int(sizes.max()),
            }
        )
    )


if __name__ == "__main__":
    main()
