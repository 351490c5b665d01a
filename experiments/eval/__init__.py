"""Metrics: circle accuracy (CE, RE, Cramer-Rao bound), which object a detection belongs to and
false detections, pose errors and filter consistency (NEES, NIS).

- `circles`: eq. (10) CE, eq. (11) RE, the Cramer-Rao bound of circle fitting
- `detections`: circles against per-beam truth labels
- `poses`: pose errors, NEES, NIS and their chi-square bounds
"""
