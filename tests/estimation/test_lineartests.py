"""The sparse description's tie rules (`lineartests.forward_selection`'s preference and
`substitutes`) on a linear system whose answer is known."""

import numpy as np
import pytest

from legcal_bench.estimation.modelgap.lineartests import forward_selection, substitutes


def _system(seed=0, rows=400):
    rng = np.random.default_rng(seed)
    N = rng.normal(size=(rows, 2))  # the nuisance columns (the offsets)
    a, other = rng.normal(size=rows), rng.normal(size=rows)
    # b is a plus 0.5 of the first nuisance column: with N in, a and b span one space
    # (the A3-like's shank twist and knee-axis tilt, apart by the hip yaw's offset).
    C = np.stack([a, a + 0.5 * N[:, 0], other], axis=1)
    z = 2.0 * a + 0.3 * N[:, 1] + 0.01 * rng.normal(size=rows)
    return z, N, C


def test_a_preferred_column_breaks_a_tie_and_the_tie_is_reported_with_its_nuisance_shift():
    z, N, C = _system()
    # Without a preference either of a, b is chosen (exactly equal drops); with one, the preferred.
    assert forward_selection(z, N, C, penalty=10.0)[0] in (0, 1)
    for pref in (0, 1):
        prefer = np.array([pref == 0, pref == 1, True])
        assert forward_selection(z, N, C, penalty=10.0, prefer=prefer, margin=1e-6) == [pref]
    ties = substitutes(z, N, C, [0], margin=1e-6)
    assert [(t["column"], t["instead_of"]) for t in ties] == [(1, 0)]
    assert ties[0]["delta_chi2"] == pytest.approx(0.0, abs=1e-6)
    # With b in place of a (coefficient 2, known to 5e-4), the first nuisance coefficient
    # moves by -2 x 0.5.
    assert ties[0]["nuisance_shift"] == pytest.approx([-1.0, 0.0], abs=2e-3)


def test_no_tie_where_one_column_explains_the_data_better():
    z, N, C = _system()
    C = C.copy()
    C[:, 1] += 0.2 * np.random.default_rng(1).normal(size=len(z))  # b no longer equivalent
    assert forward_selection(z, N, C, penalty=10.0, prefer=np.array([False, True, True]), margin=10.0) == [0]
    assert substitutes(z, N, C, [0], margin=10.0) == []
    assert substitutes(z, N, C, [], margin=10.0) == []
