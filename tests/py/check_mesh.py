#!/usr/bin/env python3
"""Loads PLY and GLB files with trimesh (an independent reader) and prints their vertex and face
counts as JSON: {"file": {"vertices": n, "faces": m}}.
usage: check_mesh.py FILE...
"""
import json
import sys

import trimesh


def counts(path):
    m = trimesh.load(path, process=False)
    if isinstance(m, trimesh.Scene):
        geoms = list(m.geometry.values())
        return {"vertices": sum(len(g.vertices) for g in geoms),
                "faces": sum(len(g.faces) for g in geoms if hasattr(g, "faces")),
                "geometries": len(geoms)}
    return {"vertices": len(m.vertices), "faces": len(m.faces) if hasattr(m, "faces") else 0, "geometries": 1}


if __name__ == "__main__":
    print(json.dumps({p: counts(p) for p in sys.argv[1:]}))
