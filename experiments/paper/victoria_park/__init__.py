"""The Victoria Park experiments (the real run: Guivant and Nebot's ute in Sydney's Victoria Park)
and the derivations of its preset, experiments/presets/victoria_park_ute.toml, from scans 1-2000.

- `real_run`: experiment `victoria-park`, EKF-SLAM on the real run against GPS
- `rfs`: experiment `victoria-park-rfs`, the full run under the published RFS protocol
- `calibration`: experiment `victoria-park-calibration`, the ute's noise and laser yaw
- `map_policy`: experiment `victoria-park-map-policy`, confirm_scans and pruning
- `split_half`: experiment `victoria-park-split-half`, the map figures judged on a half no
  setting saw
- `start`, `steering`: the start fit's length and the steering calibration (run by
  `calibration`)
- `figures`: their figures (matplotlib)
"""
