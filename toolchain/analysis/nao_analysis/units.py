"""Distinct rollouts: the resampling unit of the pooled Table 2 (docs/analysis.md).

An autonomous run starts at its demonstration's first key pose and the policy is
deterministic, so runs from nearby starts can repeat one rollout, each cut at its own length.
Such near-copies are one piece of evidence, not several: runs whose hand paths are all within
UNIT_DTW_M of each other (DTW mean distance over their common ticks) form one unit, and the
statistics and their resampling take one series per unit.

The grouping is complete linkage: every pair of runs in a unit is closer than the threshold,
so a chain of near neighbours never joins two runs that are farther apart than two runs of
different units. The threshold is a choice: docs/reproduction.md gives every verdict at each of
ROBUSTNESS_DTW_M.
"""

import numpy as np

# A near-copy: hand paths closer than 1 mm per matched pair. The numerical spread of one rollout
# is far below that, but different rollouts of one movement can come within about a millimetre
# of each other, so the cut is not clear: the verdicts are also computed at half and twice it.
UNIT_DTW_M = 1e-3
ROBUSTNESS_DTW_M = (0.5e-3, 1e-3, 2e-3)


def point_distances(a, b):
    """Euclidean distances over the last axis, the squares summed in coordinate order (the
    runtime's and the tests' reference order, so the DTW is exact to the last bit)."""
    return np.sqrt(np.sum((a - b) ** 2, axis=-1))


def dtw_mean_distances(pairs):
    """nao_rt's DTW distance (rt::dtwMeanDistance, docs/nao_rt.md) for every (a, b) of pairs
    (arrays (n, k), (m, k)), vectorised over the pairs: the minimum-cost monotone alignment of
    every point of a with every point of b, steps (1,0), (0,1), (1,1), point cost the Euclidean
    distance, divided by the number of matched pairs on that alignment; among alignments of
    equal cost the one with more pairs wins (candidates diagonal, up, left).

    The cells of a pair past its own lengths are computed on padding and never read: a cell
    depends on cells with smaller indices only."""
    out = np.empty(len(pairs))
    chunk = 512
    for c0 in range(0, len(pairs), chunk):
        part = pairs[c0:c0 + chunk]
        p = len(part)
        la = np.array([len(a) for a, _ in part])
        lb = np.array([len(b) for _, b in part])
        na, nb = la.max(), lb.max()
        k = part[0][0].shape[1]
        A = np.zeros((p, na, k))
        B = np.zeros((p, nb, k))
        for i, (a, b) in enumerate(part):
            A[i, :len(a)] = a
            B[i, :len(b)] = b
        inf = np.inf
        cost_prev = np.full((p, nb), inf)
        len_prev = np.zeros((p, nb))
        result_cost = np.empty(p)
        result_len = np.empty(p)
        rows = np.arange(p)
        for i in range(na):
            d = point_distances(A[:, i, None, :], B)  # (p, nb)
            cost = np.empty((p, nb))
            ln = np.empty((p, nb))
            for j in range(nb):
                if i == 0 and j == 0:
                    cost[:, 0] = d[:, 0]
                    ln[:, 0] = 1
                    continue
                best = np.full(p, inf)
                best_len = np.zeros(p)
                cands = []
                if i > 0 and j > 0:
                    cands.append((cost_prev[:, j - 1], len_prev[:, j - 1]))
                if i > 0:
                    cands.append((cost_prev[:, j], len_prev[:, j]))
                if j > 0:
                    cands.append((cost[:, j - 1], ln[:, j - 1]))
                for c, l in cands:
                    take = (c < best) | ((c == best) & (l > best_len))
                    best = np.where(take, c, best)
                    best_len = np.where(take, l, best_len)
                cost[:, j] = best + d[:, j]
                ln[:, j] = best_len + 1
            done = la - 1 == i
            if done.any():
                result_cost[done] = cost[rows[done], lb[done] - 1]
                result_len[done] = ln[rows[done], lb[done] - 1]
            cost_prev, len_prev = cost, ln
        out[c0:c0 + p] = result_cost / result_len
    return out


def dtw_mean_distance(a, b):
    """dtw_mean_distances of one pair; nan if either path is empty."""
    if len(a) == 0 or len(b) == 0:
        return float("nan")
    return float(dtw_mean_distances([(np.asarray(a, dtype=float), np.asarray(b, dtype=float))])[0])


def hand_path(run):
    """p_TH (n, 3), m: the robot's hand point every tick (ticks.csv ee_*, the runtime's FK)."""
    return np.column_stack([run.columns[c] for c in ("ee_x", "ee_y", "ee_z")])


def common_dtw_matrix(paths):
    """(n, n) DTW mean distances of every pair of paths over their common ticks (the shorter
    one's length; a run that repeats the beginning of a longer one is at 0), m; 0 on the diagonal."""
    n = len(paths)
    dist = np.zeros((n, n))
    pairs = [(i, k) for i in range(n) for k in range(i + 1, n)]
    if pairs:
        common = [min(len(paths[i]), len(paths[k])) for i, k in pairs]
        d = dtw_mean_distances([(paths[i][:c], paths[k][:c]) for (i, k), c in zip(pairs, common)])
        for (i, k), v in zip(pairs, d):
            dist[i, k] = dist[k, i] = v
    return dist


def complete_linkage_groups(dist, threshold_m):
    """Agglomerative complete-linkage groups of a distance matrix (n, n) cut at threshold_m:
    starting from singletons, repeatedly merge the two groups whose farthest pair is nearest,
    while that farthest pair is closer than threshold_m (ties: the pair of groups with the
    smallest first members). Every pair inside a group is then closer than threshold_m. A nan
    distance never merges. Returns index lists in order of their first member."""
    d = np.where(np.isfinite(dist), dist, np.inf)
    groups = [[i] for i in range(len(d))]
    while len(groups) > 1:
        best = None
        for a in range(len(groups)):
            for b in range(a + 1, len(groups)):
                far = d[np.ix_(groups[a], groups[b])].max()
                if far < threshold_m and (best is None or far < best[0]):
                    best = (far, a, b)
        if best is None:
            break
        _, a, b = best
        groups[a] = sorted(groups[a] + groups[b])
        del groups[b]
    return sorted(groups, key=lambda g: g[0])


def group_units(paths, threshold_m=UNIT_DTW_M):
    """Indices of the paths grouped into distinct rollouts (complete_linkage_groups of their
    common_dtw_matrix). Returns (groups, distances)."""
    dist = common_dtw_matrix(paths)
    return complete_linkage_groups(dist, threshold_m), dist


def units_of_groups(movement_runs, groups, dist):
    """(units, separation) of runs grouped by index lists: units a list of lists of runs whose
    first member is the unit's representative, its longest run (the others repeat its beginning
    and add no ticks of their own); separation a dict with the largest common DTW inside a unit
    and the smallest between units (m; None when there is no such pair), which shows how
    clear-cut the grouping is."""
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


def distinct_units(movement_runs, thresholds_m=(UNIT_DTW_M,)):
    """The runs of one movement grouped into distinct rollouts at each threshold (the DTWs
    computed once): {threshold: (units, separation)} (units_of_groups)."""
    dist = common_dtw_matrix([hand_path(r) for r in movement_runs])
    return {t: units_of_groups(movement_runs, complete_linkage_groups(dist, t), dist) for t in thresholds_m}
