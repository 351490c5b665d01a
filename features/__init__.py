"""Features from one 2D laser scan: segments, edges, lines, circles (tree trunks) and clutter.

Stands alone: imports nothing else of trunkslam.
"""

from features.errors import FeaturesError
from features.extract import METHODS, PAPER_FAITHFUL, ExtractorParams, extract_features
from features.types import Circle, Edge, Features, Line, Scan, Segment

__all__ = [
    "Scan",
    "Segment",
    "Circle",
    "Line",
    "Edge",
    "Features",
    "ExtractorParams",
    "PAPER_FAITHFUL",
    "extract_features",
    "METHODS",
    "FeaturesError",
]
