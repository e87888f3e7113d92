"""Reference intrinsics by OpenCV (findChessboardCorners, cornerSubPix, calibrateCamera with the
plumb_bob model), for the same images `xsurf calibrate intrinsics` is given.

usage: ref_calibration.py COLSxROWS SQUARE_M IMAGE...
prints one JSON object: found (per image), fx, fy, cx, cy, rms, d, width, height.
"""
import json
import sys

import cv2
import numpy as np


def main() -> None:
    cols, rows = (int(v) for v in sys.argv[1].lower().split("x"))
    square = float(sys.argv[2])
    obj = np.zeros((cols * rows, 3), np.float32)
    obj[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square
    objects, images, found, size = [], [], {}, None
    for path in sys.argv[3:]:
        grey = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
        if grey is None:
            raise SystemExit(f"{path}: OpenCV cannot read it")
        size = (grey.shape[1], grey.shape[0])
        ok, corners = cv2.findChessboardCorners(
            grey, (cols, rows), cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
        )
        found[path] = bool(ok)
        if ok:
            criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3)
            corners = cv2.cornerSubPix(grey, corners, (11, 11), (-1, -1), criteria)
            objects.append(obj)
            images.append(corners)
    out = {"found": found, "width": size[0] if size else 0, "height": size[1] if size else 0}
    if len(images) >= 3:
        rms, k, d, _, _ = cv2.calibrateCamera(objects, images, size, None, None)
        out.update(rms=rms, fx=k[0, 0], fy=k[1, 1], cx=k[0, 2], cy=k[1, 2], d=d.ravel().tolist())
    print(json.dumps(out))


if __name__ == "__main__":
    main()
