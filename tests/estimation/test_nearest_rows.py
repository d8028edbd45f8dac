"""The frame selection's nearest-frame search (`preprocess.nearest_rows`) equals the
brute-force argmin, the first index on a tie, duplicate frames included."""

import numpy as np

from legcal_bench.estimation.problem.preprocess import nearest_rows


def test_nearest_rows_is_the_brute_force_argmin_with_the_first_index_on_ties():
    rng = np.random.default_rng(3)
    Q = np.round(rng.normal(scale=0.3, size=(400, 12)), 2)  # coarse: duplicates and exact ties
    Q = np.vstack([Q, Q[:40], Q[10:20] + 0.005])
    points = np.vstack([Q[rng.choice(len(Q), 150, replace=False)],  # on frames (duplicated ones too)
                        (Q[:60] + Q[60:120]) / 2,  # midway between two frames: tied pairs
                        rng.normal(scale=0.3, size=(100, 12))])
    brute = np.argmin(((Q[:, None, :] - points[None]) ** 2).sum(-1), axis=0)
    assert np.array_equal(nearest_rows(Q, points), brute)
    assert len(np.unique(Q, axis=0)) < len(Q)  # the case has duplicates
