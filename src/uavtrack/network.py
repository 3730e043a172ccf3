"""Communication graph: UAVs i and q are neighbours when their 3-D distance is <= r_C.

The graph follows the UAVs, so it changes every step and may split into several
connected components (paper Sec. 3).
"""

from __future__ import annotations

import numpy as np


def adjacency(uavs: np.ndarray, comm_range: float) -> np.ndarray:
    """Symmetric neighbour relation from the UAVs' 3-D positions (paper Sec. 3).

    uavs: (..., N, 5) states (x, y, h used). Returns (..., N, N) bool, without self-loops.
    """
    pos = uavs[..., :3]
    diff = pos[..., :, None, :] - pos[..., None, :, :]
    dist2 = np.einsum("...ijk,...ijk->...ij", diff, diff)
    adj = dist2 <= comm_range**2
    n = adj.shape[-1]
    adj[..., np.arange(n), np.arange(n)] = False
    return adj


def complete(n: int, batch: tuple[int, ...] = ()) -> np.ndarray:
    """The complete graph on n UAVs, shape batch + (n, n), no self-loops."""
    adj = np.ones(batch + (n, n), dtype=bool)
    adj[..., np.arange(n), np.arange(n)] = False
    return adj


def closed(adj: np.ndarray) -> np.ndarray:
    """Closed neighbourhoods: each UAV is its own neighbour, (..., N, N) bool."""
    n = adj.shape[-1]
    return adj | np.eye(n, dtype=bool)


def without_self_loops(adj: np.ndarray) -> np.ndarray:
    """The relation with its diagonal cleared: a UAV is not its own radio neighbour."""
    n = adj.shape[-1]
    if not adj[..., np.arange(n), np.arange(n)].any():
        return adj
    out = adj.copy()
    out[..., np.arange(n), np.arange(n)] = False
    return out
