"""Contact neighbour search on a uniform cell grid.

Candidate (node, edge) pairs within a buffer distance are collected from the active surface edges
(body boundaries plus the faces of broken joints). The list is rebuilt when any surface node has
travelled more than half the buffer since the last build (then no pair closer than the penetration
limit can have been missed) or, a few steps after new crack faces appear.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def surface_nodes(edges, edge_active, n_nodes):
    """Indices of the nodes on active edges."""
    flag = np.zeros(n_nodes, dtype=np.bool_)
    for e in range(edges.shape[0]):
        if edge_active[e]:
            flag[edges[e, 0]] = True
            flag[edges[e, 1]] = True
    return np.nonzero(flag)[0]


@njit(cache=True)
def node_normals(x, edges, edge_active):
    """Outward unit normal of every surface node (mean of its active edges' normals; zero elsewhere)."""
    return _normals(x, edges, np.nonzero(edge_active)[0])


@njit(cache=True)
def _normals(x, edges, act):
    """Unit mean of the outward normals of the edges act at each of their nodes (zero elsewhere)."""
    node_normal = np.zeros((x.shape[0], 2))
    for k in range(act.shape[0]):
        e = act[k]
        p = edges[e, 0]
        q = edges[e, 1]
        ex = x[q, 0] - x[p, 0]
        ey = x[q, 1] - x[p, 1]
        L = math.sqrt(ex * ex + ey * ey)
        node_normal[p, 0] += ey / L
        node_normal[p, 1] -= ex / L
        node_normal[q, 0] += ey / L
        node_normal[q, 1] -= ex / L
    for n in range(x.shape[0]):
        L = math.sqrt(node_normal[n, 0] ** 2 + node_normal[n, 1] ** 2)
        if L > 0.0:
            node_normal[n, 0] /= L
            node_normal[n, 1] /= L
    return node_normal


@njit(cache=True)
def build_pairs(x, edges, edge_active, edge_tri, snodes, node_vertex, node_body, node_tri, tri,
                body_fracturable, buffer):
    """A fresh search, the definition refresh_pairs (what the integrator uses) is tested against:
    all (node, edge) pairs with node-to-segment distance <= buffer, excluding a node against an
    edge of its own triangle, an edge of a triangle that has a copy of the node's mesh vertex, and pairs
    inside a body that cannot fracture.

    Also returns the outward unit normal of every surface node (mean of its active edges' normals),
    which the contact kernel uses to reject an edge facing the same way (node-to-segment corner
    ambiguity). Returns (pair_node, pair_edge, node_normal), the pairs ordered by node (as snodes)
    and, per node, by edge index.
    """
    pn, pe = grid_pairs(x, edges, np.nonzero(edge_active)[0], snodes, buffer, edge_tri, node_vertex,
                        node_body, node_tri, tri, body_fracturable)
    return pn, pe, node_normals(x, edges, edge_active)


@njit(cache=True)
def grid_pairs(x, edges, act, snodes, buffer, edge_tri, node_vertex, node_body, node_tri, tri,
               body_fracturable):
    """The pairs of build_pairs between the nodes snodes and the edges act (both ascending), on a
    uniform cell grid."""
    ne = act.shape[0]
    nn = snodes.shape[0]
    if ne == 0 or nn == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    xmin = np.inf
    ymin = np.inf
    xmax = -np.inf
    ymax = -np.inf
    Lsum = 0.0
    for k in range(nn):
        n = snodes[k]
        xmin = min(xmin, x[n, 0])
        xmax = max(xmax, x[n, 0])
        ymin = min(ymin, x[n, 1])
        ymax = max(ymax, x[n, 1])
    for k in range(ne):
        e = act[k]
        p = edges[e, 0]
        q = edges[e, 1]
        Lsum += math.sqrt((x[q, 0] - x[p, 0]) ** 2 + (x[q, 1] - x[p, 1]) ** 2)
    xmin -= buffer
    ymin -= buffer
    xmax += buffer
    ymax += buffer
    # Cells about one mean edge long, but never more than ~4 cells per surface node.
    cs = Lsum / ne + 2.0 * buffer
    area = (xmax - xmin) * (ymax - ymin)
    cs_min = math.sqrt(area / (4.0 * nn + 1.0))
    if cs < cs_min:
        cs = cs_min
    ncx = int((xmax - xmin) / cs) + 1
    ncy = int((ymax - ymin) / cs) + 1
    counts = np.zeros(ncx * ncy + 1, np.int64)
    for pass_ in range(2):
        if pass_ == 1:
            for c in range(ncx * ncy):
                counts[c + 1] += counts[c]
            fill = counts[:-1].copy()
            cell_edges = np.empty(counts[ncx * ncy], np.int64)
            # The edge's geometry copied beside each cell entry (p, q - p, |q - p|^2), so the query
            # below streams through memory: almost every candidate is rejected on distance, and
            # gathering each one's nodes from x dominated the rebuild once fragments filled the grid.
            cell_geo = np.empty((counts[ncx * ncy], 5))
            # and what _excluded asks of the edge: its triangle, that triangle's mesh vertices, its body
            cell_ref = np.empty((counts[ncx * ncy], 5), np.int64)
        for k in range(ne):
            e = act[k]
            p = edges[e, 0]
            q = edges[e, 1]
            i0 = int((min(x[p, 0], x[q, 0]) - buffer - xmin) / cs)
            i1 = int((max(x[p, 0], x[q, 0]) + buffer - xmin) / cs)
            j0 = int((min(x[p, 1], x[q, 1]) - buffer - ymin) / cs)
            j1 = int((max(x[p, 1], x[q, 1]) + buffer - ymin) / cs)
            i0 = max(i0, 0)
            j0 = max(j0, 0)
            i1 = min(i1, ncx - 1)
            j1 = min(j1, ncy - 1)
            if pass_ == 1:
                ex = x[q, 0] - x[p, 0]
                ey = x[q, 1] - x[p, 1]
                l2 = ex * ex + ey * ey
            for ii in range(i0, i1 + 1):
                for jj in range(j0, j1 + 1):
                    c = jj * ncx + ii
                    if pass_ == 0:
                        counts[c + 1] += 1
                    else:
                        slot = fill[c]
                        cell_edges[slot] = e
                        cell_geo[slot, 0] = x[p, 0]
                        cell_geo[slot, 1] = x[p, 1]
                        cell_geo[slot, 2] = ex
                        cell_geo[slot, 3] = ey
                        cell_geo[slot, 4] = l2
                        te = edge_tri[e]
                        cell_ref[slot, 0] = te
                        cell_ref[slot, 1] = node_vertex[tri[te, 0]]
                        cell_ref[slot, 2] = node_vertex[tri[te, 1]]
                        cell_ref[slot, 3] = node_vertex[tri[te, 2]]
                        cell_ref[slot, 4] = node_body[p]
                        fill[c] += 1
    npair = 0
    out_n = np.empty(16, np.int64)
    out_e = np.empty(16, np.int64)
    b2 = buffer * buffer
    for k in range(nn):
        n = snodes[k]
        xn = x[n, 0]
        yn = x[n, 1]
        tn = node_tri[n]
        vn = node_vertex[n]
        bn = node_body[n]
        rigid_n = not body_fracturable[bn]
        ii = int((xn - xmin) / cs)
        jj = int((yn - ymin) / cs)
        c = jj * ncx + ii
        for m in range(counts[c], counts[c + 1]):
            ex = cell_geo[m, 2]
            ey = cell_geo[m, 3]
            rx = xn - cell_geo[m, 0]
            ry = yn - cell_geo[m, 1]
            s = (rx * ex + ry * ey) / cell_geo[m, 4]
            s = min(max(s, 0.0), 1.0)
            dx = rx - s * ex
            dy = ry - s * ey
            if dx * dx + dy * dy > b2:
                continue
            # Excluded: an edge of the node's own triangle; an edge of a triangle that has a copy of
            # the node's mesh vertex (at the edge's ends the node-to-edge projection is ambiguous, the
            # faces of a broken joint being kept apart by the joint's compressive branch, and at the
            # opposite vertex it would read the whole altitude as a penetration); a pair inside a body
            # that cannot fracture.
            if (tn == cell_ref[m, 0] or vn == cell_ref[m, 1] or vn == cell_ref[m, 2] or vn == cell_ref[m, 3]
                    or (rigid_n and bn == cell_ref[m, 4])):
                continue
            e = cell_edges[m]
            if npair == out_n.shape[0]:
                tmp_n = np.empty(2 * npair, np.int64)
                tmp_e = np.empty(2 * npair, np.int64)
                tmp_n[:npair] = out_n
                tmp_e[:npair] = out_e
                out_n = tmp_n
                out_e = tmp_e
            out_n[npair] = n
            out_e[npair] = e
            npair += 1
    return out_n[:npair].copy(), out_e[:npair].copy()


@njit(cache=True)
def filter_pairs(x, cand_node, cand_edge, edges, edge_active, surface, buffer):
    """The pairs build_pairs would return (in the same order, by the same arithmetic) taken from a
    candidate list that holds every pair within the distance: those whose node is on an active edge
    (surface), whose edge is active and whose distance is <= buffer now."""
    keep = np.empty(cand_node.shape[0], np.bool_)
    b2 = buffer * buffer
    m = 0
    for k in range(cand_node.shape[0]):
        n = cand_node[k]
        e = cand_edge[k]
        keep[k] = False
        if not (surface[n] and edge_active[e]):
            continue
        p = edges[e, 0]
        q = edges[e, 1]
        ex = x[q, 0] - x[p, 0]
        ey = x[q, 1] - x[p, 1]
        l2 = ex * ex + ey * ey
        rx = x[n, 0] - x[p, 0]
        ry = x[n, 1] - x[p, 1]
        s = (rx * ex + ry * ey) / l2
        s = min(max(s, 0.0), 1.0)
        dx = rx - s * ex
        dy = ry - s * ey
        if dx * dx + dy * dy > b2:
            continue
        keep[k] = True
        m += 1
    pn = np.empty(m, np.int64)
    pe = np.empty(m, np.int64)
    m = 0
    for k in range(cand_node.shape[0]):
        if keep[k]:
            pn[m] = cand_node[k]
            pe[m] = cand_edge[k]
            m += 1
    return pn, pe


@njit(cache=True)
def refresh_pairs(x, edges, edge_active, edge_tri, node_vertex, node_body, node_tri, tri, body_fracturable,
                  buffer, margin, cand_node, cand_edge, x_cand, all_edges, edge_nodes, edge_rigid):
    """The contact list of build_pairs at x, through a candidate list of every pair (active or not)
    within buffer + margin at x_cand.

    A pair closer than buffer now was closer than buffer + 2 d at x_cand, d the largest travel of a
    node since, so while 2 d <= margin the candidates hold it, and the list is the candidates
    filtered: crack faces that appear need no new search (they made the rebuilds of a fragmenting
    specimen, every few steps, the larger part of a run). Otherwise the candidates are searched
    afresh at x (x_cand is updated in place). all_edges: every edge index; edge_nodes: every node on
    an edge (both ascending); edge_rigid: the edges of bodies that cannot fracture, the only ones
    whose nodes' normals contact_forces reads (a fracturable body's node takes its direction from
    its triangle), so the normals are summed over those alone.
    Returns (pair_node, pair_edge, node_normal, surface nodes, cand_node, cand_edge).
    """
    d2 = 0.0
    for k in range(edge_nodes.shape[0]):
        i = edge_nodes[k]
        dx = x[i, 0] - x_cand[i, 0]
        dy = x[i, 1] - x_cand[i, 1]
        if dx * dx + dy * dy > d2:
            d2 = dx * dx + dy * dy
    if cand_node.shape[0] == 0 or 4.0 * d2 > margin * margin:
        cand_node, cand_edge = grid_pairs(x, edges, all_edges, edge_nodes, buffer + margin, edge_tri,
                                          node_vertex, node_body, node_tri, tri, body_fracturable)
        for k in range(edge_nodes.shape[0]):
            i = edge_nodes[k]
            x_cand[i, 0] = x[i, 0]
            x_cand[i, 1] = x[i, 1]
    snodes = surface_nodes(edges, edge_active, x.shape[0])
    surface = np.zeros(x.shape[0], np.bool_)
    for k in range(snodes.shape[0]):
        surface[snodes[k]] = True
    pn, pe = filter_pairs(x, cand_node, cand_edge, edges, edge_active, surface, buffer)
    m = 0
    for e in range(edges.shape[0]):
        if edge_active[e] and edge_rigid[e]:
            m += 1
    act = np.empty(m, np.int64)
    m = 0
    for e in range(edges.shape[0]):
        if edge_active[e] and edge_rigid[e]:
            act[m] = e
            m += 1
    return pn, pe, _normals(x, edges, act), snodes, cand_node, cand_edge
