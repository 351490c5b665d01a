"""File formats and dataset readers, and the writers of every result (atomic).

- `sequence_file`: the run as one `.npz` (datasets/FORMAT.md): `load_sequence`, `save_sequence`
- `victoria_park`: the Victoria Park dataset as a `slam.Sequence`, and its reference detections
- `rosbag`: a robot's ROS bag (ROS 1, ROS 2 sqlite3 or MCAP) as a `slam.Sequence`
- `paths`: where the real datasets live (`TRUNKSLAM_DATA`)
- `writers`: atomic files, Markdown/CSV tables, the features JSON
- `results`: a SLAM run's trajectory (TUM, CSV) and map (CSV)
- `provenance`: machine, package versions, git commit
"""
