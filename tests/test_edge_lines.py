"""Steps 3-5 of the edge fits, each against a naive search: borrowed lines, the features' and
the flags' line distances, confirmed lines (:mod:`tiledsimplify.core.edge_lines`)."""

import numpy as np

from tiledsimplify.core import edge_fit, edge_lines

from edge_scenes import fitted_scan, two_ring_ids


def _naive_borrow(X, dn, dn_cnt, candidate, distance, angle, line, local, width, corner):
    """Step 3 by Python loops: the two-ring of each candidate its own fit does not flag,
    lenders (not corners), numpy distances."""
    out, angle_out = distance.copy(), angle.copy()
    own = edge_fit.band(distance, angle, width)
    for p in np.flatnonzero(candidate & ~own):
        for q in sorted(two_ring_ids(dn, dn_cnt, p)):
            if distance[q] <= width and angle[q] >= edge_fit.SOFT_ANGLE and not corner[q]:
                d = np.linalg.norm(np.cross(X[p] - line[q, :3], line[q, 3:])) / local[p]
                if d < out[p] and d <= edge_lines.BORROW_WIDTH * width:
                    out[p], angle_out[p] = d, angle[q]
    return out, angle_out


def test_borrow_equals_a_naive_search(data_dir):
    X, st, cand, dist, ang, line, local, corner = fitted_scan(data_dir)
    n = len(X)
    fitted = np.isfinite(dist)
    np.testing.assert_allclose(np.linalg.norm(line[fitted, 3:], axis=1), 1.0, atol=1e-12)
    assert corner.sum() >= 3  # corner fits are there, and lend to nobody
    for width in (1.0, 0.5):
        out, out_angle = np.empty(n), np.empty(n)
        edge_lines.borrow(X, st.dn, st.dn_cnt, dist, ang, line, local, width,
                        edge_fit.band(dist, ang, width), corner, out, out_angle)
        ref, ref_angle = _naive_borrow(X, st.dn, st.dn_cnt, cand, dist, ang, line, local,
                                       width, corner)
        np.testing.assert_allclose(out, ref, rtol=1e-12)
        np.testing.assert_array_equal(out_angle, ref_angle)
        lent = cand & ~fitted & np.isfinite(out)
        assert lent.sum() > 20  # the scan has failed fits beside good ones
        refit = fitted & (out < dist)  # fits that found a farther edge than a neighbour's
        assert refit.sum() > 5
        assert (out <= dist).all()
        own = edge_fit.band(dist, ang, width)
        assert (out[own] == dist[own]).all()  # flagged by their own fit: left alone


def test_line_distances_equal_a_naive_search(data_dir):
    """Step 4 by Python loops: every lender's two-ring, numpy distances to its line in units
    of the larger of its local spacing and the cloud's."""
    X, st, cand, dist, ang, line, local, corner = fitted_scan(data_dir)
    n = len(X)
    for width, spacing in ((1.0, 0.0), (1.0, float(np.median(local[cand]))), (0.5, 1e9)):
        out = np.full(n, np.inf)
        edge_lines.line_distances(X, st.dn, st.dn_cnt, dist, ang, line, local, width, spacing,
                                corner, out)
        ref = np.full(n, np.inf)
        lenders = np.flatnonzero((dist <= width) & (ang >= edge_fit.SOFT_ANGLE) & ~corner)
        assert lenders.size > 100
        for q in lenders:
            ring = np.array(sorted(two_ring_ids(st.dn, st.dn_cnt, q)))
            d = np.linalg.norm(np.cross(X[ring] - line[q, :3], line[q, 3:]), axis=1)
            ref[ring] = np.minimum(ref[ring], d / max(local[q], spacing))
        np.testing.assert_allclose(out, ref, rtol=1e-12)
        if spacing < 1e9:
            reached = np.isfinite(out)
            assert (out[reached] <= width).sum() > 1.2 * (dist <= width).sum()


def _naive_reach(X, dn, dn_cnt, q, reach):
    """The points within ``reach`` of ``X[q]`` reached from it through the local mesh, by a
    Python set (any order)."""
    seen, todo, reached = {int(q)}, [int(q)], []
    while todo:
        r = todo.pop()
        reached.append(r)
        for t in dn[r, :dn_cnt[r]].tolist():
            if t not in seen:
                seen.add(t)
                if np.sum((X[t] - X[q]) ** 2) <= reach * reach:
                    todo.append(t)
    assert len(seen) < edge_lines.MAX_REACH_POINTS  # the walk's cap never cut this one
    return reached


def _naive_nearest_lines(X, dn, dn_cnt, lender, line, reach, spacing):
    """:func:`edge_lines.nearest_line_distances` by Python sets: each lender's points reached
    through the local mesh within ``reach`` of it, each point's ``FLAG_FITS`` nearest of the
    lenders reaching it (ties to the lower index), its least distance to their lines."""
    reached = [[] for _ in range(len(X))]
    for q in np.flatnonzero(lender):
        for r in _naive_reach(X, dn, dn_cnt, q, reach):
            reached[r].append((float(np.sum((X[r] - X[q]) ** 2)), int(q)))
    out = np.full(len(X), np.inf)
    for p, near in enumerate(reached):
        for _, q in sorted(near)[:edge_lines.FLAG_FITS]:
            out[p] = min(out[p], np.linalg.norm(np.cross(X[p] - line[q, :3], line[q, 3:])))
    return out / spacing


def test_nearest_line_distances_equal_a_naive_search(data_dir):
    """The flags' distances by Python loops, on the noisy Fandisk scan; fewer lenders (every
    other one) reach fewer points, farther."""
    X, st, cand, dist, ang, line, local, corner = fitted_scan(data_dir)
    lender = (dist <= 1.0) & (ang >= edge_fit.SOFT_ANGLE) & ~corner
    assert lender.sum() > 100
    spacing = float(np.median(local[cand]))
    reached = []
    for mask, reach in ((lender, 4.0 * spacing), (lender, 2.0 * spacing),
                        (lender & (np.arange(len(X)) % 2 == 0), 4.0 * spacing)):
        out = np.empty(len(X))
        edge_lines.nearest_line_distances(X, st.dn, st.dn_cnt, mask, line, reach, spacing, out)
        ref = _naive_nearest_lines(X, st.dn, st.dn_cnt, mask, line, reach, spacing)
        np.testing.assert_allclose(out, ref, rtol=1e-12)
        reached.append(np.isfinite(out).sum())
    assert reached[0] > 3 * lender.sum() and reached[0] > max(reached[1:]), reached


def _naive_confirmed(X, dn, dn_cnt, fit, sure, line, reach, offset, min_cos):
    """:func:`edge_lines.confirmed_lines` by Python sets: a fit not sure of itself lends where
    another fit reached through the local mesh within ``reach`` of it has a line within
    ``offset`` of its point's foot on its own line and as parallel as ``min_cos``."""
    out = sure.copy()
    for q in np.flatnonzero(fit & ~sure):
        u = line[q, 3:]
        foot = line[q, :3] + np.dot(X[q] - line[q, :3], u) * u
        for r in _naive_reach(X, dn, dn_cnt, q, reach):
            if (r != q and fit[r] and abs(np.dot(line[r, 3:], u)) >= min_cos
                    and np.linalg.norm(np.cross(foot - line[r, :3], line[r, 3:])) <= offset):
                out[q] = True
                break
    return out


def test_confirmed_lines_equal_a_naive_search(data_dir):
    """Which far fits lend, by Python loops, on the noisy Fandisk scan: most fits within two
    widths of their line are confirmed, fewer by a tighter offset, and none with no second
    fit to confirm them (every fit sure, or none)."""
    X, st, cand, dist, ang, line, local, corner = fitted_scan(data_dir)
    fit = (dist <= 2.0) & (ang >= edge_fit.SOFT_ANGLE) & ~corner
    sure = fit & (dist <= 1.0)
    spacing = float(np.median(local[cand]))
    far = (fit & ~sure).sum()
    assert far > 100
    cos20 = np.cos(np.radians(20.0))
    counts = []
    for offset in (0.3 * spacing, 0.05 * spacing):
        out = np.empty(len(X), dtype=bool)
        edge_lines.confirmed_lines(X, st.dn, st.dn_cnt, fit, sure, line, 3.0 * spacing, offset,
                                 cos20, out)
        ref = _naive_confirmed(X, st.dn, st.dn_cnt, fit, sure, line, 3.0 * spacing, offset,
                               cos20)
        np.testing.assert_array_equal(out, ref)
        assert (out & ~fit).sum() == 0 and (out & sure).sum() == sure.sum()
        counts.append(int((out & ~sure).sum()))
    assert far > counts[0] > counts[1] > 0, (far, counts)
    alone = np.empty(len(X), dtype=bool)
    for f in (sure, np.zeros(len(X), dtype=bool)):
        edge_lines.confirmed_lines(X, st.dn, st.dn_cnt, f, f, line, 3.0 * spacing,
                                 0.3 * spacing, cos20, alone)
        np.testing.assert_array_equal(alone, f)
