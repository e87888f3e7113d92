"""Independent checks of our DICOM surfaces, with pydicom and trimesh.

  check_surface_dcm.py compare SURFACE.dcm MERGED.ply [XRAY.dcm]
      the Surface Scan Mesh against the PLY it was made from (points, triangles, coordinates),
      and the radiograph's patient, study and frame beside it: JSON facts on stdout
  check_surface_dcm.py cloud POINTS.dcm MERGED.ply
      the Surface Scan Point Cloud against the PLY's points: counts, coordinates, colours
  check_surface_dcm.py relabel SURFACE.dcm OUT.dcm [SOP_CLASS]
      the same data set labelled as a Surface Segmentation, the IOD that dciodvfy knows and
      that shares the Surface Mesh module (or as SOP_CLASS)
  check_surface_dcm.py series DIR
      findscu's responses (rsp*.dcm) in DIR: each series' modality, UID and frame
"""
import hashlib
import json
import sys
from pathlib import Path

import numpy as np
import pydicom
import trimesh


def compare(surface, ply, xray=None):
    d = pydicom.dcmread(surface)
    item = d.SurfaceSequence[0]
    pts = item.SurfacePointsSequence[0]
    n = int(pts.NumberOfSurfacePoints)
    coords = np.frombuffer(pts.PointCoordinatesData, dtype="<f4").reshape(-1, 3)
    tri = np.frombuffer(item.SurfaceMeshPrimitivesSequence[0].LongTrianglePointIndexList, dtype="<u4").reshape(-1, 3)
    mesh = trimesh.load(ply, process=False)
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces, dtype=np.int64)
    same_shape = coords.shape == v.shape
    facts = {
        "sop_class": str(d.SOPClassUID),
        "modality": d.Modality,
        "points": n,
        "coordinates": int(coords.shape[0]),
        "triangles": int(tri.shape[0]),
        "ply_points": int(v.shape[0]),
        "ply_triangles": int(f.shape[0]),
        # The surface in mm against the PLY in m, as float32 allows.
        "max_coordinate_difference_m": float(np.abs(coords.astype(np.float64) / 1000.0 - v).max()) if same_shape else None,
        "max_coordinate_m": float(np.abs(v).max()) if len(v) else 0.0,
        "triangles_equal": bool(tri.shape == f.shape and np.array_equal(tri.astype(np.int64) - 1, f)),
        "index_min": int(tri.min()) if tri.size else None,
        "index_max": int(tri.max()) if tri.size else None,
        "acquisition_type": [d.SurfaceScanAcquisitionTypeCodeSequence[0].CodeValue,
                             d.SurfaceScanAcquisitionTypeCodeSequence[0].CodingSchemeDesignator,
                             d.SurfaceScanAcquisitionTypeCodeSequence[0].CodeMeaning],
        "lab": [int(x) for x in item.RecommendedDisplayCIELabValue],
        "presentation_type": item.RecommendedPresentationType,
        "study_uid": str(d.StudyInstanceUID),
        "series_uid": str(d.SeriesInstanceUID),
        "patient_id": str(d.PatientID),
        "patient_name": str(d.PatientName),
        "frame_uid": str(d.FrameOfReferenceUID),
        "transfer_syntax": str(d.file_meta.TransferSyntaxUID),
    }
    if xray:
        x = pydicom.dcmread(xray)
        facts.update({
            "xray_modality": x.Modality,
            "xray_study_uid": str(x.StudyInstanceUID),
            "xray_series_uid": str(x.SeriesInstanceUID),
            "xray_patient_id": str(x.get("PatientID", "")),
            "xray_frame_uid": str(x.get("FrameOfReferenceUID", "")),
            "xray_pixels": int(x.pixel_array.size),
        })
    return facts


def cloud(points_dcm, ply):
    d = pydicom.dcmread(points_dcm)
    pts = d.SurfacePointsSequence[0]
    coords = np.frombuffer(pts.PointCoordinatesData, dtype="<f4").reshape(-1, 3)
    v = np.asarray(trimesh.load(ply, process=False).vertices, dtype=np.float64)
    # US beyond 64 KiB: a PACS storing it in Explicit VR gives it as UN (PS3.5 6.2.2), bytes.
    el = d.get((0x0080, 0x0007))
    lab = None
    if el is not None:
        raw = el.value
        lab = np.frombuffer(raw, dtype="<u2") if isinstance(raw, (bytes, bytearray)) else np.asarray(raw, dtype="<u2")
    return {
        "lab_md5": hashlib.md5(lab.tobytes()).hexdigest() if lab is not None else None,
        "sop_class": str(d.SOPClassUID),
        "points": int(pts.NumberOfSurfacePoints),
        "ply_points": int(v.shape[0]),
        "colours": (len(lab) // 3) if lab is not None else 0,
        "max_coordinate_difference_m": float(np.abs(coords.astype(np.float64) / 1000.0 - v).max())
        if coords.shape == v.shape else None,
        "series_uid": str(d.SeriesInstanceUID),
        "transfer_syntax": str(d.file_meta.TransferSyntaxUID),
    }


def relabel(src, dst, sop_class="1.2.840.10008.5.1.4.1.1.66.5"):
    d = pydicom.dcmread(src)
    d.SOPClassUID = sop_class
    d.file_meta.MediaStorageSOPClassUID = d.SOPClassUID
    d.Modality = "SEG"
    d.save_as(dst)
    return {"written": str(dst)}


def series(folder):
    out = []
    for f in sorted(Path(folder).glob("rsp*.dcm")):
        d = pydicom.dcmread(f)
        out.append({
            "modality": str(d.get("Modality", "")),
            "series_uid": str(d.get("SeriesInstanceUID", "")),
            "study_uid": str(d.get("StudyInstanceUID", "")),
        })
    return {"series": out}


def main():
    cmd, args = sys.argv[1], sys.argv[2:]
    if cmd == "compare":
        r = compare(*args)
    elif cmd == "cloud":
        r = cloud(*args)
    elif cmd == "relabel":
        r = relabel(*args)
    elif cmd == "series":
        r = series(*args)
    else:
        raise SystemExit(f"unknown command {cmd}")
    print(json.dumps(r))


if __name__ == "__main__":
    main()
