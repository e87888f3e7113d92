"""Checks a camera_calibration YAML file against the layout ROS 2's camera_calibration_parsers
writes (and camera_info_manager reads), field for field, with an independent YAML parser.

Usage: check_calibration_yaml.py FILE
Prints JSON: the parsed values. Exits non-zero with the difference when the layout differs.
"""
import json
import sys

import yaml

# A file as camera_calibration_parsers (ROS 2, parse_yml.cpp) writes it.
REFERENCE = """image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [700.1, 0, 322.4, 0, 701.2, 237.6, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.12, 0.05, 0.0005, -0.0003, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [700.1, 0, 322.4, 0, 0, 701.2, 237.6, 0, 0, 0, 1, 0]
"""


def fail(msg):
    print(msg, file=sys.stderr)
    sys.exit(1)


def main():
    ref = yaml.safe_load(REFERENCE)
    text = open(sys.argv[1]).read()
    ours = yaml.safe_load(text)
    if list(ours.keys()) != list(ref.keys()):
        fail(f"keys {list(ours.keys())} != {list(ref.keys())}")
    for key, want in ref.items():
        got = ours[key]
        if isinstance(want, dict):
            if list(got.keys()) != list(want.keys()):
                fail(f"{key}: keys {list(got.keys())} != {list(want.keys())}")
            if not all(isinstance(got[k], int) for k in ("rows", "cols")):
                fail(f"{key}: rows/cols are not integers")
            if len(got["data"]) != got["rows"] * got["cols"]:
                fail(f"{key}: {len(got['data'])} values for {got['rows']}x{got['cols']}")
            if not all(isinstance(v, (int, float)) for v in got["data"]):
                fail(f"{key}: data is not numeric")
            if key != "distortion_coefficients" and (got["rows"], got["cols"]) != (want["rows"], want["cols"]):
                fail(f"{key}: {got['rows']}x{got['cols']} != {want['rows']}x{want['cols']}")
        elif type(got) is not type(want):
            fail(f"{key}: {type(got).__name__} != {type(want).__name__}")
    k, p = ours["camera_matrix"]["data"], ours["projection_matrix"]["data"]
    if [p[0], p[2], p[5], p[6]] != [k[0], k[2], k[4], k[5]]:
        fail("projection_matrix does not carry camera_matrix")
    # Flow-style sequences, as the ROS writer emits them.
    for key in ("camera_matrix", "distortion_coefficients", "rectification_matrix", "projection_matrix"):
        block = text.split(key + ":", 1)[1]
        if "data: [" not in block.split("\n", 4)[3]:
            fail(f"{key}: data is not a flow sequence")
    print(json.dumps(ours))


main()
