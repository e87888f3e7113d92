#!/usr/bin/env python3
"""Reads our DICOM with pydicom (an independent reader) and writes variants for the reader's
tests with pydicom as the writer.

usage: check_dicom.py FILE OUTDIR
prints JSON: what pydicom reads in FILE, and the variants written in OUTDIR:
  rle.dcm          the same image, RLE Lossless (compressed by pydicom)
  implicit12.dcm   Implicit VR Little Endian, 12-bit MONOCHROME2 signed, rescale, a VOI LUT
  jpegls.dcm       JPEG-LS transfer syntax (no pure-Rust codec: must be refused, naming it)
  nopixels.dcm     no PixelData element
"""
import json
import os
import sys

import numpy as np
import pydicom
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.encaps import encapsulate
from pydicom.uid import (ExplicitVRLittleEndian, ImplicitVRLittleEndian, JPEGLSLossless, RLELossless,
                         generate_uid)

src, out = sys.argv[1], sys.argv[2]
ds = pydicom.dcmread(src)
px = ds.pixel_array
facts = {
    "rows": int(ds.Rows), "columns": int(ds.Columns),
    "bits_allocated": int(ds.BitsAllocated), "bits_stored": int(ds.BitsStored), "high_bit": int(ds.HighBit),
    "photometric": str(ds.PhotometricInterpretation),
    "window_center": float(ds.WindowCenter), "window_width": float(ds.WindowWidth),
    "sop_class": str(ds.SOPClassUID), "modality": str(ds.Modality),
    "transfer_syntax": str(ds.file_meta.TransferSyntaxUID),
    "shape": list(px.shape), "min": int(px.min()), "max": int(px.max()), "sum": int(px.astype(np.int64).sum()),
    "source_detector_mm": float(ds.DistanceSourceToDetector),
    "imager_pixel_spacing_mm": [float(v) for v in ds.ImagerPixelSpacing],
    "exposure_time_ms": int(ds.ExposureTime),
    "acquisition_datetime": str(ds.AcquisitionDateTime),
}

os.makedirs(out, exist_ok=True)

rle = pydicom.dcmread(src)
rle.compress(RLELossless)
rle.save_as(os.path.join(out, "rle.dcm"))

# A small image written by pydicom from scratch: 12-bit signed MONOCHROME2, implicit VR.
meta = FileMetaDataset()
meta.MediaStorageSOPClassUID = "1.2.840.10008.5.1.4.1.1.1.1"
meta.MediaStorageSOPInstanceUID = generate_uid()
meta.TransferSyntaxUID = ImplicitVRLittleEndian
d = Dataset()
d.file_meta = meta
d.SOPClassUID = meta.MediaStorageSOPClassUID
d.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
d.Modality = "DX"
d.Rows, d.Columns = 3, 4
d.SamplesPerPixel = 1
d.PhotometricInterpretation = "MONOCHROME2"
d.BitsAllocated, d.BitsStored, d.HighBit, d.PixelRepresentation = 16, 12, 11, 1
d.RescaleSlope, d.RescaleIntercept = "2", "100"
values = np.array([[-2048, -1, 0, 1], [100, 200, 300, 2047], [5, 6, 7, 8]], dtype=np.int16)
d.PixelData = values.tobytes()
lut = Dataset()
lut.LUTDescriptor = [4, 98, 8]
lut.LUTData = np.array([0, 100, 200, 255], dtype=np.uint16).tobytes()
d.VOILUTSequence = [lut]
pydicom.dcmwrite(os.path.join(out, "implicit12.dcm"), d, enforce_file_format=True)
facts["implicit12_values"] = values.flatten().tolist()

jls = pydicom.dcmread(src)
jls.file_meta.TransferSyntaxUID = JPEGLSLossless
jls.PixelData = encapsulate([b"\xff\xd8" + b"\x00" * 64 + b"\xff\xd9"])
jls["PixelData"].VR = "OB"
jls.save_as(os.path.join(out, "jpegls.dcm"))

nop = pydicom.dcmread(src)
del nop.PixelData
nop.save_as(os.path.join(out, "nopixels.dcm"))

print(json.dumps(facts))
