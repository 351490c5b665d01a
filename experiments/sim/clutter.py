"""The objects that fool a trunk extractor on real data, added to a simulated park with their
labels: posts and thin poles far away, car corners, bushes and people.

`clutter_park()` is the tree park of Table 3 (`experiments/scenes/tree_park.json`, unchanged)
with the objects of `CLUTTER` added after its own: its trunks keep their labels 0-7 and every
existing scene and table is as it was. Each added object carries its class as its `kind`, so
the per-beam truth (`scan_labels`, `Scene.label_kind`) says which class each beam hit. The
trunk map it should give is `Scene.truth_trunks` (the posts and legs are circles too, so
`truth_landmarks` holds them; they are not trees).

Sizes and where they come from (the scan plane is the Cycab's laser at 1.2 m):
  post  lamp posts 0.10-0.20 m across (street-lighting columns of the European standard
        EN 40-2 are 0.1-0.2 m at the base; radius 0.05-0.10 m here) and sign poles of a 60 mm
        tube (radius 0.03 m); all taller than the scan plane, placed 8-22 m beyond the route,
        where 1-3 beams of 0.5 deg reach them (a 0.15 m post at 17 m spans 0.5 deg).
  car   a family car's body, 1.8 m x 4.5 m (a VW Golf is 1.79 m x 4.28 m, a Toyota Camry
        1.84 m x 4.88 m) and 1.45 m tall, so the scan plane cuts it; from any place the laser
        sees one or two of its sides: a corner of two perpendicular short lines.
  bush  the tree park's seven bushes, and two more made by `scene.make_bush` (radius 0.8 m
        and 0.5 m, 12 vertices, irregularity 0.35 as the park's own), 1.5 m tall.
  leg   a standing person as seen by a laser at leg height (the model of people detectors
        that scan legs): two legs of 0.12 m across (a calf of about 0.37 m girth, the adult
        mean of anthropometric surveys such as ANSUR II) 0.3 m apart centre to centre (about
        a hip breadth). People are static here (the simulator has no moving objects) and are
        drawn at every height, so the 1.2 m laser sees legs where a real one would see a hip.
"""

from __future__ import annotations

import math

import numpy as np

from experiments.sim.scene import BushObject, CircleObject, Scene, WallObject, load_scene, make_bush

__all__ = ["CLUTTER_CLASSES", "CLUTTER", "car_outline", "clutter_park", "legs"]

# the class of each kind: what the per-class figures are grouped by
CLUTTER_CLASSES = {
    "trunk": "trunk",
    "pillar": "trunk",
    "post": "post",
    "car": "car",
    "bush": "bush",
    "leg": "person",
    "wall": "wall",
    "baluster": "wall",
}
CAR_WIDTH_M, CAR_LENGTH_M, CAR_HEIGHT_M = 1.8, 4.5, 1.45
LEG_RADIUS_M, LEG_GAP_M = 0.06, 0.3

# (name, kind, where, size): posts (centre, radius), cars (centre, heading of the long side),
# people (centre, heading of the line through the legs); tree park coordinates (m, rad).
CLUTTER = {
    "posts": (
        ("P1", (36.0, 2.0), 0.075),  # 10 m east of the route's east end
        ("P2", (44.0, -5.0), 0.05),
        ("P3", (-3.0, -9.0), 0.1),  # south-west, beyond the first bush
        ("P4", (8.0, -16.0), 0.075),
        ("P5", (22.0, -17.0), 0.03),  # a sign pole
        ("P6", (38.0, 9.0), 0.03),
    ),
    "cars": (
        ("C1", (3.0, -13.0), math.pi / 2),  # two cars parked side by side, south
        ("C2", (5.6, -13.0), math.pi / 2),
        ("C3", (38.0, -9.0), math.radians(30.0)),
    ),
    "people": (
        ("H1", (18.0, 9.2), 0.0),
        ("H2", (6.5, -7.5), math.pi / 3),
        ("H3", (30.5, 4.0), math.pi / 2),
    ),
    "bushes": (("B8", (36.0, -14.0), 0.8, 308), ("B9", (7.0, 10.5), 0.5, 309)),
}


def car_outline(center_xy, heading_rad: float) -> np.ndarray:
    """(4, 2) corners of a car body (`CAR_WIDTH_M` x `CAR_LENGTH_M`) at `center_xy`, its long
    side along `heading_rad`, counter-clockwise, m."""
    c, s = math.cos(heading_rad), math.sin(heading_rad)
    half = np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]]) * [CAR_LENGTH_M / 2, CAR_WIDTH_M / 2]
    return np.asarray(center_xy, dtype=np.float64) + half @ np.array([[c, s], [-s, c]])


def legs(name: str, center_xy, heading_rad: float) -> tuple[CircleObject, CircleObject]:
    """The two legs of a standing person at `center_xy`, the line through them along
    `heading_rad` (`LEG_RADIUS_M`, `LEG_GAP_M` apart)."""
    d = 0.5 * LEG_GAP_M * np.array([math.cos(heading_rad), math.sin(heading_rad)])
    c = np.asarray(center_xy, dtype=np.float64)
    return (
        CircleObject(f"{name}L", c - d, LEG_RADIUS_M, "leg"),
        CircleObject(f"{name}R", c + d, LEG_RADIUS_M, "leg"),
    )


def clutter_park(base: Scene | str = "tree_park") -> Scene:
    """`base` (the tree park) with the objects of `CLUTTER` added after its own (module doc)."""
    sc = base if isinstance(base, Scene) else load_scene(base)
    posts = [CircleObject(n, c, r, "post") for n, c, r in CLUTTER["posts"]]
    people = [leg for n, c, h in CLUTTER["people"] for leg in legs(n, c, h)]
    cars = [
        WallObject(n, car_outline(c, h), "car", closed=True, height_m=CAR_HEIGHT_M)
        for n, c, h in CLUTTER["cars"]
    ]
    bushes = [
        BushObject(n, make_bush(c, r, np.random.default_rng(seed)), height_m=1.5)
        for n, c, r, seed in CLUTTER["bushes"]
    ]
    return Scene(
        circles=(*sc.circles, *posts, *people),
        walls=(*sc.walls, *cars),
        bushes=(*sc.bushes, *bushes),
        scan_positions=sc.scan_positions,
        scan_position_names=sc.scan_position_names,
        name=f"{sc.name}_clutter",
        description=sc.description + "\nWith clutter: experiments.sim.clutter.",
    )
