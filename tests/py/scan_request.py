#!/usr/bin/env python3
"""Publishes one ScanEvent on /scan/request from a Cyclone DDS peer (a hospital controller
asking c_arm_pose for a scan), after waiting for the subscriber to match.

usage: scan_request.py START|END|ABORT
"""
import pathlib
import sys
import time

from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.topic import Topic
from cyclonedds.util import duration

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from ros_types import Header, ScanEvent, Time  # noqa: E402

EVENTS = {"START": 0, "END": 1, "ABORT": 2}


def main(kind):
    dp = DomainParticipant(0)
    qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10))
    w = DataWriter(dp, Topic(dp, "rt/scan/request", ScanEvent), qos=qos)
    t0 = time.time()
    while w.get_matched_subscriptions() == [] and time.time() - t0 < 20:
        time.sleep(0.1)
    if not w.get_matched_subscriptions():
        sys.exit("no subscriber of /scan/request matched in 20 s")
    now = time.time()
    stamp = Time(sec=int(now), nanosec=int((now % 1) * 1e9))
    w.write(ScanEvent(header=Header(stamp=stamp, frame_id="table"), scan_id=0, event=EVENTS[kind]))
    time.sleep(1.0)  # let the reliable writer deliver before the participant goes


if __name__ == "__main__":
    main(sys.argv[1])
