"""The `trunkslam bench` commands: scripts that measure and print figures (never tests).

- `extract`: extractor throughput on the real Victoria Park scans, and numba's cold compile
- `association`: time per scan of each associator at Victoria Park scale
- `slam`: EKF-SLAM time per scan against the size of the map
- `raycast`: the simulator's ray casting
- `startup`: how long the command line takes to answer (presets, help, a refused input)
"""
