#!/usr/bin/env python3
"""use_sim_time and /rosout with an independent DDS peer (run inside netns-run by tests/dds.rs).

Starts `c_arm_pose` with use_sim_time:=true, publishes /clock (rosgraph_msgs/msg/Clock) from
1000 s at twice real time, and checks that the /tf it publishes carries the simulated time and
that its log records (the end of the scan) arrive on /rosout as rcl_interfaces/msg/Log.
usage: sim_time.py BIN_DIR
prints JSON: tf stamps seen (first, last, count), rosout records of the node.
"""
import json
import os
import pathlib
import signal
import subprocess
import sys
import time

from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from ros_types import Clock, Log, TFMessage, Time  # noqa: E402

RELIABLE = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(1000))
BEST_EFFORT = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(1000))

bin_dir = pathlib.Path(sys.argv[1])
dp = DomainParticipant(0)
tf_r = DataReader(dp, Topic(dp, "rt/tf", TFMessage), qos=BEST_EFFORT)
log_r = DataReader(dp, Topic(dp, "rt/rosout", Log), qos=RELIABLE)
clock_w = DataWriter(dp, Topic(dp, "rt/clock", Clock), qos=BEST_EFFORT)
env = dict(os.environ, ROS_LOCALHOST_ONLY="1")
proc = subprocess.Popen([str(bin_dir / "c_arm_pose"), "--ros-args", "-p", "use_sim_time:=true", "-p",
                         "start_delay_s:=0.5", "-p", "rate_hz:=50.0"],
                        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env)
stamps, logs = [], []
sim = 1000.0
t_end = time.time() + 12
while time.time() < t_end:
    clock_w.write(Clock(clock=Time(sec=int(sim), nanosec=int((sim % 1) * 1e9))))
    sim += 0.1
    for m in tf_r.take(N=100):
        if isinstance(m, TFMessage) and m.transforms:
            st = m.transforms[0].header.stamp
            stamps.append(st.sec + st.nanosec * 1e-9)
    for m in log_r.take(N=100):
        if isinstance(m, Log):
            logs.append({"name": m.name, "level": int(m.level), "msg": m.msg})
    if any("ended" in l["msg"] for l in logs):
        break
    time.sleep(0.05)
proc.send_signal(signal.SIGTERM)
out, _ = proc.communicate(timeout=30)
print(json.dumps({"tf_count": len(stamps), "tf_first": min(stamps, default=None), "tf_last": max(stamps, default=None),
                  "sim_last": sim, "logs": logs, "exit": proc.returncode,
                  "node_output_tail": out.decode(errors="replace")[-2000:]}))
