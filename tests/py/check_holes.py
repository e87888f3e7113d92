#!/usr/bin/env python3
"""Counts the boundary edges of a merged surface that lie inside the cameras' own surfaces
(holes and open seams), with trimesh and scipy: independent of xsurf's mesh code.

A boundary edge of MERGED (an edge of one triangle only) is *interior* when its midpoint lies on
some camera's surface (within --on of one of that camera's vertices) and farther than --rim from
that camera's own boundary: the cameras' surfaces together cover it, so the merged surface
should too. The others are on the outer rim.

usage: check_holes.py MERGED.ply CAM.ply... [--on M] [--rim M] [--table-z M]
prints JSON: {"boundary_edges", "interior", "interior_table", "camera_boundary_edges": [...],
              "spacing", "on", "rim"}; "interior_table" counts the interior edges with |z| below
              --table-z (the flat tabletop, z = 0 in `table`).
"""
import argparse
import json

import numpy as np
import trimesh
from scipy.spatial import cKDTree


def boundary_edges(mesh):
    """Edges (vertex index pairs) used by exactly one face."""
    e = np.sort(mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    uniq, counts = np.unique(e, axis=0, return_counts=True)
    return uniq[counts == 1]


def load(path):
    return trimesh.load(path, process=False)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("merged")
    ap.add_argument("cameras", nargs="+")
    ap.add_argument("--on", type=float, default=None, help="on a camera's surface within this, m")
    ap.add_argument("--rim", type=float, default=None, help="away from its boundary by this, m")
    ap.add_argument("--table-z", type=float, default=0.001, help="|z| below this is the table, m")
    a = ap.parse_args()

    merged = load(a.merged)
    cams = [load(p) for p in a.cameras]
    # The cameras' sample spacing: the median edge length of their meshes.
    spacing = float(np.median(np.concatenate([c.edges_unique_length for c in cams])))
    on = a.on if a.on is not None else 2.0 * spacing
    rim = a.rim if a.rim is not None else 4.0 * spacing

    def interior_mask(points):
        inside = np.zeros(len(points), dtype=bool)
        for c in cams:
            d_on, _ = cKDTree(c.vertices).query(points)
            be = boundary_edges(c)
            rim_pts = c.vertices[np.unique(be)]
            d_rim, _ = cKDTree(rim_pts).query(points) if len(rim_pts) else (np.full(len(points), np.inf), None)
            inside |= (d_on < on) & (d_rim > rim)
        return inside

    be = boundary_edges(merged)
    mid = merged.vertices[be].mean(axis=1)
    inside = interior_mask(mid)
    table = np.abs(mid[:, 2]) < a.table_z
    cam_be = [int(len(boundary_edges(c))) for c in cams]
    print(json.dumps({
        "boundary_edges": int(len(be)),
        "interior": int(inside.sum()),
        "interior_table": int((inside & table).sum()),
        "camera_boundary_edges": cam_be,
        "spacing": spacing,
        "on": on,
        "rim": rim,
    }))


if __name__ == "__main__":
    main()
