"""Union-find over (N,) int64 parent arrays, for the numba kernels that merge near-duplicates (the skeleton's
coincident nodes, the discontinuity ranking's collinear segments)."""

from numba import njit


@njit(cache=True)
def find_root(parent, i):
    """The root of element i in the forest parent (N,) int64, halving the path on the way."""
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i
