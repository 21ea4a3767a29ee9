"""Distinct rollouts: the resampling unit of the pooled Table 2 (docs/analysis.md).

An autonomous run starts at its demonstration's first key pose and the policy is
deterministic, so runs from one start repeat one rollout, each cut at its own length. Such
near-copies are one piece of evidence, not several: runs whose hand paths are within
UNIT_DTW_M of each other (DTW mean distance over their common ticks) form one unit, and the
statistics, their bootstrap and their permutation test take one series per unit.
"""

import numpy as np

# A near-copy: hand paths closer than 1 mm per matched pair. Distinct starts of one movement
# differ by centimetres, the numerical spread of one rollout by far less than a millimetre.
UNIT_DTW_M = 1e-3


def dtw_mean_distance(a, b):
    """Dynamic-time-warping distance of two paths of points, as nao_rt scores a rollout
    (docs/nao_rt.md): the minimum-cost monotone alignment of every point of a (n, 3) with every
    point of b (m, 3), steps (1,0), (0,1), (1,1), point cost the Euclidean distance, divided by
    the number of matched pairs on that alignment; among alignments of equal cost the one with
    more pairs wins. Returns nan if either path is empty.

    Computed along anti-diagonals (every cell of one depends only on the two before it), so
    the loop runs n + m times, not n * m."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    n, m = len(a), len(b)
    if n == 0 or m == 0:
        return float("nan")
    d = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)
    cost = np.full((n, m), np.inf)
    pairs = np.zeros((n, m), dtype=np.int64)
    cost[0, 0], pairs[0, 0] = d[0, 0], 1
    for s in range(1, n + m - 1):
        i = np.arange(max(0, s - m + 1), min(n, s + 1))
        j = s - i
        best = np.full(len(i), np.inf)
        best_pairs = np.zeros(len(i), dtype=np.int64)
        # Candidates in the order diagonal, up (i-1, j), left (i, j-1): lower cost wins, then
        # more pairs (an alignment of equal total cost with more pairs has the lower mean).
        for di, dj in ((1, 1), (1, 0), (0, 1)):
            ok = (i >= di) & (j >= dj)
            c = np.where(ok, cost[np.maximum(i - di, 0), np.maximum(j - dj, 0)], np.inf)
            p = np.where(ok, pairs[np.maximum(i - di, 0), np.maximum(j - dj, 0)], 0)
            take = (c < best) | ((c == best) & (p > best_pairs))
            best = np.where(take, c, best)
            best_pairs = np.where(take, p, best_pairs)
        cost[i, j] = best + d[i, j]
        pairs[i, j] = best_pairs + 1
    return float(cost[n - 1, m - 1] / pairs[n - 1, m - 1])


def hand_path(run):
    """p_TH (n, 3), m: the robot's hand point every tick (ticks.csv ee_*, the runtime's FK)."""
    return np.column_stack([run.columns[c] for c in ("ee_x", "ee_y", "ee_z")])


def common_dtw(path_a, path_b):
    """DTW mean distance of two hand paths over their common ticks (the shorter one's length):
    a run that repeats the beginning of a longer one is at distance 0 from it."""
    k = min(len(path_a), len(path_b))
    return dtw_mean_distance(path_a[:k], path_b[:k])


def group_units(paths, threshold_m=UNIT_DTW_M):
    """Indices of the paths grouped into distinct rollouts: a path within threshold_m (common
    DTW) of any path of a group joins it, transitively. Returns (groups, distances): groups a
    list of index lists in order of their first member, distances the (n, n) common DTW matrix."""
    n = len(paths)
    dist = np.zeros((n, n))
    parent = list(range(n))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i in range(n):
        for k in range(i + 1, n):
            dist[i, k] = dist[k, i] = common_dtw(paths[i], paths[k])
            if dist[i, k] < threshold_m:
                parent[root(k)] = root(i)
    groups = {}
    for i in range(n):
        groups.setdefault(root(i), []).append(i)
    return sorted(groups.values(), key=lambda g: g[0]), dist


def distinct_units(movement_runs, threshold_m=UNIT_DTW_M):
    """The runs of one movement grouped into distinct rollouts. Returns (units, separation):
    units a list of lists of runs whose first member is the unit's representative, its longest
    run (the others repeat its beginning and add no ticks of their own); separation a dict with
    the largest common DTW inside a unit and the smallest between units (m; None when there is
    no such pair), which shows how clear-cut the grouping is."""
    groups, dist = group_units([hand_path(r) for r in movement_runs], threshold_m)
    units = []
    for g in groups:
        members = [movement_runs[i] for i in g]
        # Longest first; among equals the first in path order, so the choice is deterministic.
        members.sort(key=lambda r: (-r.n_ticks, r.path))
        units.append(members)
    label = [0] * len(movement_runs)
    for u, g in enumerate(groups):
        for i in g:
            label[i] = u
    n = len(movement_runs)
    within = [dist[i, k] for i in range(n) for k in range(i + 1, n) if label[i] == label[k]]
    between = [dist[i, k] for i in range(n) for k in range(i + 1, n) if label[i] != label[k]]
    return units, {"max_dtw_within_unit_m": float(max(within)) if within else None,
                   "min_dtw_between_units_m": float(min(between)) if between else None}
