"""The two-ring helpers of the edge fits (:mod:`tiledsimplify.core.two_ring`)."""

import numpy as np

from tiledsimplify.core import two_ring
from tiledsimplify.core.simplify import neighbourhoods, scale_of

from edge_scenes import roof


def test_nearest_distances_equal_kdtree():
    from scipy.spatial import cKDTree
    X = roof(np.random.default_rng(3), 800)
    X -= X.mean(0)
    st = neighbourhoods(X, scale_of(X))
    nn = np.empty(len(X))
    two_ring.nearest_distances(X, st.start, st.cnt, st.pool, nn)
    np.testing.assert_allclose(nn, cKDTree(X).query(X, k=2)[0][:, 1], rtol=1e-12)
