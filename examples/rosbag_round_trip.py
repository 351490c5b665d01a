"""Your own robot: a ROS 2 bag in, trajectory and map out. A simulated drive around the tree
park is written as a ROS 2 bag (LaserScan, nav_msgs/Odometry, /tf_static) with the `rosbags`
library's writer, converted back by `read_rosbag` (what `trunkslam convert rosbag` runs), and
driven through EKF-SLAM; the error is against the simulator's truth.

    python examples/rosbag_round_trip.py [OUT_DIR]

Writes OUT_DIR/drive (the bag; default OUT_DIR: a temp dir). The same from the command line:

    trunkslam convert rosbag OUT_DIR/drive --scan /scan --odom /odom --out seq.npz
    trunkslam slam seq.npz --out slam_out
"""

import sys
import tempfile
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import Writer  # storage_plugin=StoragePlugin.MCAP writes MCAP instead
from rosbags.typesys import Stores, get_typestore

from experiments.eval.poses import pose_errors
from experiments.io.rosbag import read_rosbag
from experiments.sim import CycabParams, simulate_cycab_run
from slam import interpolate_poses, run_slam, se2

out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="trunkslam_"))
out.mkdir(parents=True, exist_ok=True)
drive = simulate_cycab_run(np.random.default_rng(0), "tree_park", CycabParams(n_scans=120))

ts = get_typestore(Stores.ROS2_HUMBLE)
msg = ts.types  # message classes by type name


def header(t_s: float, frame: str):
    ns = round(t_s * 1e9)  # ROS time: the drive's own clock
    stamp = msg["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
    return msg["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)


def vector(x=0.0, y=0.0, z=0.0):
    return msg["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)


no_turn = msg["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
origin = msg["geometry_msgs/msg/Pose"](
    position=msg["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0), orientation=no_turn
)
bag, topics = out / "drive", {}
with Writer(bag, version=9) as w:  # a bag folder: metadata.yaml and drive.db3

    def write(topic, t_s, message):
        if topic not in topics:
            topics[topic] = w.add_connection(topic, message.__msgtype__, typestore=ts)
        data = ts.serialize_cdr(message, message.__msgtype__)
        w.write(topics[topic], round(t_s * 1e9), data)

    # the laser's mounting: base_link -> laser, 0.5 m above the ground
    x, y, _ = drive.laser_pose
    mount = msg["geometry_msgs/msg/Transform"](translation=vector(x, y, 0.5), rotation=no_turn)
    tf = msg["geometry_msgs/msg/TransformStamped"](
        header=header(0.0, "base_link"), child_frame_id="laser", transform=mount
    )
    write("/tf_static", 0.0, msg["tf2_msgs/msg/TFMessage"](transforms=[tf]))
    # wheel odometry as a twist: the car's speed and its yaw rate v tan(steer) / L (the pose
    # is left at the origin: the conversion reads the twist)
    yaw_rate = drive.odo_speed * np.tan(drive.odo_steer) / drive.vehicle.wheelbase_m
    for t, v, w_z in zip(drive.odo_t, drive.odo_speed, yaw_rate):
        twist = msg["geometry_msgs/msg/Twist"](linear=vector(v), angular=vector(z=w_z))
        odom = msg["nav_msgs/msg/Odometry"](
            header=header(t, "odom"),
            child_frame_id="base_link",
            pose=msg["geometry_msgs/msg/PoseWithCovariance"](pose=origin, covariance=np.zeros(36)),
            twist=msg["geometry_msgs/msg/TwistWithCovariance"](
                twist=twist, covariance=np.zeros(36)
            ),
        )
        write("/odom", t, odom)
    # the scans: float32 ranges, +inf for no return
    for t, r in zip(drive.scan_t, drive.scan_ranges):
        scan = msg["sensor_msgs/msg/LaserScan"](
            header=header(t, "laser"),
            angle_min=drive.scan_angle_min,
            angle_max=drive.scan_angle_min + (r.size - 1) * drive.scan_angle_increment,
            angle_increment=drive.scan_angle_increment,
            time_increment=0.0,
            scan_time=0.2,
            range_min=0.1,
            range_max=drive.scan_max_range,
            ranges=np.nan_to_num(r, nan=np.inf).astype(np.float32),
            intensities=np.zeros(0, dtype=np.float32),
        )
        write("/scan", t, scan)
print(f"wrote {bag}: {drive.n_scans} scans, {drive.odo_t.size} odometry samples")

run = read_rosbag(bag, scan="/scan", odom="/odom")  # laser pose from /tf_static
print(f"converted: {run.summary()}")

log = run_slam(run.sequence, features="paper")  # starts at the origin: no GPS in this bag
truth = interpolate_poses(drive.scan_t, drive.truth_t, drive.truth_pose)
start = se2.inverse(truth[0])
truth_from_start = np.array([se2.compose(start, p) for p in truth])
err = pose_errors(log.pose, truth_from_start)[1:]
dx, dy, dtheta = np.mean(np.abs(err), axis=0)
print(f"landmarks: {log.landmark_xy.shape[0]}")
print(f"mean absolute error: dx {dx:.4f} m, dy {dy:.4f} m, dtheta {dtheta:.5f} rad")
print(f"largest position error: {np.hypot(err[:, 0], err[:, 1]).max():.4f} m")
