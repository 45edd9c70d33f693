"""The KKT bookkeeping of sgd_limit_points on hand-made gradients."""

import numpy as np

from proofs_checks._sgd import kkt_analysis


def test_kkt_analysis_splits_active_and_interior():
    w = np.array([0.5, -0.5, 0.1, 0.4999999])
    g = np.array([-1.0, 2.0, 1e-4, -0.3])
    a = kkt_analysis(g, np.full(4, 0.01), w, np.full(4, -0.5), np.full(4, 0.5))
    assert a["active"].tolist() == [True, True, False, True]
    assert a["at_hi"].tolist() == [True, False, False, True] and a["at_lo"].tolist() == [False, True, False, False]
    np.testing.assert_allclose(a["z"], g / 0.01)
