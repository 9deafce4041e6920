"""Furnished apartments in metres, for visual navigation.

The visual experiments of the paper "Safe Multi-Agent Navigation guided by Goal-Conditioned
Safe Reinforcement Learning" run in four apartment scenes of a 3D simulator. These layouts are
our own stand-ins: several rooms joined by doors, 10 to 15 m across, each with 15 to 25 pieces of
furniture (couches, tables, counters, beds, shelves, ...). To the collision world every wall
and every piece is just a box; the renderer also knows their heights and materials.

Walls are 0.12 m thick and full height (2.6 m); doors are gaps of about 1 m. The cost radius is
1 m, as in the paper's visual tasks. :data:`APARTMENT_ENV_KWARGS` holds the environment
settings that suit metres: agents of radius 0.2 m that move at most 0.25 m per axis and step, and
a goal reached within 0.5 m.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Dict, List, Optional, Sequence, Tuple

from ..sensors.scene import Colour, Material, Room, Scene, SceneBox

Box = Tuple[float, float, float, float]

#: Wall thickness in metres.
WALL = 0.12
#: Ceiling (and wall) height in metres.
CEILING = 2.6

#: Environment settings for apartments (metres): see the module docstring.
APARTMENT_ENV_KWARGS: Dict[str, float] = {"agent_radius": 0.2, "action_scale": 0.25, "goal_threshold": 0.5}

# ---------------------------------------------------------------------------------- materials
FLOORS: Dict[str, Material] = {
    "wood": Material((164, 116, 76), stripe=0.18, stripe_contrast=0.08, band=1.2, band_contrast=0.05),
    "oak": Material((200, 164, 116), stripe=0.2, stripe_contrast=0.07, band=1.0, band_contrast=0.05),
    "tile": Material((216, 214, 204), stripe=0.4, band=0.4, checker=0.09),
    "slate": Material((120, 124, 132), stripe=0.5, band=0.5, checker=0.1),
    "bath": Material((164, 200, 212), stripe=0.2, band=0.2, checker=0.12),
    "carpet_blue": Material((112, 124, 164), stripe=0.5, band=0.5, checker=0.03),
    "carpet_green": Material((116, 150, 110), stripe=0.5, band=0.5, checker=0.03),
    "carpet_rose": Material((176, 124, 132), stripe=0.5, band=0.5, checker=0.03),
}

WALLS: Dict[str, Material] = {
    "cream": Material((232, 222, 192), stripe=0.3, stripe_contrast=0.05, skirting=0.1),
    "sage": Material((172, 196, 156), stripe=0.3, stripe_contrast=0.05, skirting=0.1),
    "sky": Material((164, 190, 222), stripe=0.3, stripe_contrast=0.05, skirting=0.1),
    "terracotta": Material((214, 146, 112), stripe=0.3, stripe_contrast=0.05, skirting=0.1),
    "lavender": Material((194, 176, 222), stripe=0.3, stripe_contrast=0.05, skirting=0.1),
    "mustard": Material((222, 192, 112), stripe=0.3, stripe_contrast=0.05, skirting=0.1),
    "white_tiles": Material((226, 236, 240), stripe=0.25, band=0.25, checker=0.07),
    "grey": Material((190, 190, 196), stripe=0.6, stripe_contrast=0.06, skirting=0.1),
}


def _m(colour: Colour, **kw) -> Material:
    return Material(colour, **kw)


#: Furniture kinds: height in metres, side material, top material.
FURNITURE: Dict[str, Tuple[float, Material, Material]] = {
    "couch": (0.85, _m((50, 108, 120), band=0.42, band_contrast=0.15),
        _m((72, 138, 150), stripe=0.7, stripe_contrast=0.12)),
    "armchair": (0.85, _m((190, 144, 56), band=0.42, band_contrast=0.15), _m((214, 176, 84))),
    "table": (0.76, _m((104, 68, 42), stripe=0.12, stripe_contrast=0.3),
        _m((142, 96, 58), stripe=0.12, stripe_contrast=0.1)),
    "coffee_table": (0.45, _m((62, 62, 66)), _m((150, 172, 182), stripe=0.3, stripe_contrast=0.06)),
    "chair": (0.9, _m((92, 62, 40), band=0.3, band_contrast=0.2), _m((122, 84, 52))),
    "tv_stand": (0.55, _m((42, 42, 46), stripe=0.4, stripe_contrast=0.2), _m((30, 30, 34))),
    "counter": (0.92, _m((234, 232, 224), stripe=0.6, stripe_contrast=0.12),
        _m((88, 88, 96), stripe=0.15, band=0.15, checker=0.06)),
    "island": (0.92, _m((120, 88, 58), stripe=0.5, stripe_contrast=0.15),
        _m((206, 204, 198), stripe=0.3, band=0.3, checker=0.04)),
    "fridge": (1.85, _m((202, 206, 212), band=1.1, band_contrast=0.1), _m((182, 182, 186))),
    "bed": (0.55, _m((150, 108, 78)), _m((226, 228, 238), stripe=0.25, band=0.25, checker=0.07)),
    "nightstand": (0.55, _m((172, 130, 90), band=0.2, band_contrast=0.15), _m((186, 144, 100))),
    "wardrobe": (2.1, _m((214, 188, 148), stripe=0.5, stripe_contrast=0.12), _m((200, 176, 140))),
    "bookshelf": (1.9, _m((140, 70, 50), stripe=0.09, band=0.35, band_contrast=0.25, checker=0.15), _m((120, 60, 42))),
    "desk": (0.75, _m((236, 236, 236), stripe=0.55, stripe_contrast=0.1), _m((222, 222, 216))),
    "plant": (1.1, _m((56, 128, 60), stripe=0.1, band=0.12, checker=0.3),
        _m((78, 160, 70), stripe=0.1, band=0.1, checker=0.3)),
    "bathtub": (0.55, _m((242, 242, 242)), _m((196, 222, 234))),
    "vanity": (0.85, _m((196, 176, 146), stripe=0.45, stripe_contrast=0.12), _m((232, 232, 232))),
    "toilet": (0.45, _m((246, 246, 246)), _m((232, 236, 240))),
    "piano": (1.2, _m((24, 24, 28), band=0.6, band_contrast=0.3), _m((44, 44, 50))),
    "dresser": (0.9, _m((180, 118, 88), band=0.25, band_contrast=0.2), _m((196, 134, 100))),
    "cabinet": (1.0, _m((90, 110, 130), stripe=0.45, stripe_contrast=0.15), _m((104, 124, 144))),
    "washer": (0.85, _m((240, 240, 244), band=0.42, band_contrast=0.08), _m((226, 226, 230))),
}


@dataclass(frozen=True)
class Furniture:
    """One piece of furniture: a kind from :data:`FURNITURE`, its footprint and an optional top colour."""

    kind: str
    box: Box
    top_colour: Optional[Colour] = None

    def __post_init__(self) -> None:
        if self.kind not in FURNITURE:
            raise ValueError(f"unknown furniture kind {self.kind!r}; known: {', '.join(sorted(FURNITURE))}")
        x0, y0, x1, y1 = self.box
        if not (x0 < x1 and y0 < y1):
            raise ValueError(f"furniture {self.kind!r} footprint must have x0 < x1 and y0 < y1, got {self.box}")

    def scene_box(self) -> SceneBox:
        h, side, top = FURNITURE[self.kind]
        if self.top_colour is not None:
            top = Material(self.top_colour, top.stripe, top.stripe_contrast, top.band, top.band_contrast, top.checker)
        return SceneBox(self.box, h, side, top)


@dataclass(frozen=True)
class Apartment:
    """A furnished apartment: a :class:`~safe_mapf_envs.scenario.Layout` that also knows how it looks.

    Attributes:
        name: map name, used in env ids (``Safe<name>-v0``).
        size: extent ``(width, height)`` in metres; ``x`` to the east, ``y`` to the south.
        walls: wall boxes (outer and inner), full height.
        rooms: floor regions with their floor and wall materials.
        furniture: the pieces.
        description: one line for tables and docs.
        cost_radius: radius of influence of the cost (1 m, as in the paper's visual tasks).
        resize_factor: nominal cell size in metres; the geodesic oracle rasterises at a fifth
            of it (0.1 m).
    """

    name: str
    size: Tuple[float, float]
    walls: Tuple[Box, ...]
    rooms: Tuple[Room, ...]
    furniture: Tuple[Furniture, ...]
    description: str = ""
    cost_radius: float = 1.0
    resize_factor: float = 0.5
    ceiling_height: float = CEILING
    camera_height: float = 1.2
    sensor_range: float = 10.0
    _boxes: Tuple[Box, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        w, h = self.size
        boxes = tuple(tuple(float(c) for c in b) for b in self.walls) + tuple(
            tuple(float(c) for c in f.box) for f in self.furniture
        )
        for b in boxes:
            if not (0 <= b[0] < b[2] <= w and 0 <= b[1] < b[3] <= h):
                raise ValueError(f"apartment {self.name!r}: box {b} is empty or leaves the {w:g} x {h:g} m world")
        object.__setattr__(self, "_boxes", boxes)

    def boxes(self) -> List[Box]:
        """Walls then furniture, as ``(x0, y0, x1, y1)`` in metres."""
        return list(self._boxes)

    @cached_property
    def _scene(self) -> Scene:
        wall = WALLS["grey"]
        boxes = [SceneBox(b, self.ceiling_height, wall, wall, room_coloured=True) for b in self.walls]
        boxes += [f.scene_box() for f in self.furniture]
        return Scene(
            self.size, boxes, self.rooms[1:], self.rooms[0],
            ceiling_height=self.ceiling_height, camera_height=self.camera_height,
            max_range=self.sensor_range, agent_height=0.9, raster_resolution=0.04, name=self.name,
        )

    def scene(self) -> Scene:
        """The renderable scene (built once and shared)."""
        return self._scene


# ---------------------------------------------------------------------------------- builders
def hwall(y: float, x0: float, x1: float, doors: Sequence[Tuple[float, float]] = ()) -> List[Box]:
    """A wall along ``x`` from ``x0`` to ``x1``, centred on ``y``, with door gaps ``(xa, xb)``."""
    return _segments(x0, x1, doors, lambda a, b: (a, y - WALL / 2, b, y + WALL / 2))


def vwall(x: float, y0: float, y1: float, doors: Sequence[Tuple[float, float]] = ()) -> List[Box]:
    """A wall along ``y`` from ``y0`` to ``y1``, centred on ``x``, with door gaps ``(ya, yb)``."""
    return _segments(y0, y1, doors, lambda a, b: (x - WALL / 2, a, x + WALL / 2, b))


def _segments(lo, hi, doors, make) -> List[Box]:
    out, start = [], lo
    for a, b in sorted(doors):
        if not (lo < a < b < hi):
            raise ValueError(f"door ({a}, {b}) must lie inside the wall span ({lo}, {hi})")
        out.append(make(start, a))
        start = b
    out.append(make(start, hi))
    return out


def outer_walls(w: float, h: float) -> List[Box]:
    """The four outer walls, inside the ``w x h`` world."""
    return [(0.0, 0.0, w, WALL), (0.0, h - WALL, w, h), (0.0, WALL, WALL, h - WALL), (w - WALL, WALL, w, h - WALL)]


def room(box: Box, floor: str, walls: str, name: str = "") -> Room:
    return Room(box, FLOORS[floor], WALLS[walls], name)


def F(kind: str, x0: float, y0: float, x1: float, y1: float, top: Optional[Colour] = None) -> Furniture:
    return Furniture(kind, (x0, y0, x1, y1), top)


APARTMENTS: Dict[str, Apartment] = {}


def _add(a: Apartment) -> None:
    APARTMENTS[a.name] = a


# Apartment0, 12 x 9 m: living and dining room on the west, kitchen and bedroom on the east.
_add(Apartment(
    "Apartment0", (12.0, 9.0),
    walls=tuple(outer_walls(12.0, 9.0) + vwall(7.0, WALL, 9.0 - WALL, doors=[(1.8, 2.8), (6.0, 7.0)])
                + hwall(4.6, 7.06, 12.0 - WALL, doors=[(9.1, 10.1)])),
    rooms=(
        room((0, 0, 12, 9), "wood", "cream", "living"),
        room((7, 0, 12, 4.6), "tile", "sage", "kitchen"),
        room((7, 4.6, 12, 9), "carpet_blue", "sky", "bedroom"),
    ),
    furniture=(
        F("bookshelf", 0.12, 0.7, 0.52, 2.7),
        F("table", 2.6, 1.3, 4.4, 2.2),
        F("chair", 2.85, 0.75, 3.3, 1.2), F("chair", 3.7, 0.75, 4.15, 1.2),
        F("chair", 2.85, 2.3, 3.3, 2.75), F("chair", 3.7, 2.3, 4.15, 2.75),
        F("plant", 6.25, 0.2, 6.85, 0.8),
        F("couch", 0.9, 5.2, 3.7, 6.1),
        F("coffee_table", 1.6, 6.6, 3.0, 7.3),
        F("tv_stand", 1.0, 8.4, 3.6, 8.88),
        F("armchair", 4.6, 6.0, 5.5, 6.9),
        F("plant", 0.2, 8.3, 0.75, 8.85),
        F("counter", 7.4, 0.12, 11.88, 0.75),
        F("fridge", 11.18, 0.9, 11.88, 1.6),
        F("island", 8.4, 2.2, 10.4, 3.1),
        F("bed", 9.7, 6.0, 11.88, 7.6, top=(206, 92, 96)),
        F("nightstand", 11.38, 5.45, 11.88, 5.9), F("nightstand", 11.38, 7.7, 11.88, 8.15),
        F("wardrobe", 7.06, 7.5, 7.7, 8.88),
        F("desk", 8.2, 8.3, 9.4, 8.88),
    ),
    description="12 x 9 m: living/dining room, kitchen with island, bedroom",
))

# Apartment1, 14 x 10 m: open-plan loft with a study nook; bedroom, hall and bathroom on the east.
_add(Apartment(
    "Apartment1", (14.0, 10.0),
    walls=tuple(outer_walls(14.0, 10.0)
                + vwall(9.0, WALL, 6.0, doors=[(2.2, 3.2)])
                + hwall(6.0, 8.94, 14.0 - WALL, doors=[(9.8, 10.8)])
                + vwall(11.5, 6.06, 10.0 - WALL, doors=[(7.4, 8.4)])
                + hwall(4.0, WALL, 3.56, doors=[(1.3, 2.3)])
                + vwall(3.5, WALL, 3.94)),
    rooms=(
        room((0, 0, 14, 10), "oak", "cream", "loft"),
        room((0, 0, 3.5, 4.0), "carpet_green", "terracotta", "study"),
        room((9, 0, 14, 6), "carpet_rose", "lavender", "bedroom"),
        room((9, 6, 11.5, 10), "slate", "grey", "hall"),
        room((11.5, 6, 14, 10), "bath", "white_tiles", "bathroom"),
        room((0, 6.6, 5.5, 10), "tile", "mustard", "kitchen"),
    ),
    furniture=(
        F("desk", 0.3, 0.12, 1.9, 0.75),
        F("bookshelf", 3.0, 0.6, 3.44, 3.0),
        F("chair", 0.9, 0.95, 1.35, 1.4),
        F("counter", 0.12, 9.25, 4.4, 9.88),
        F("fridge", 4.5, 9.2, 5.2, 9.88),
        F("island", 1.2, 7.2, 3.4, 8.1),
        F("table", 5.8, 6.6, 7.4, 7.6),
        F("chair", 6.0, 6.05, 6.45, 6.5), F("chair", 6.8, 7.7, 7.25, 8.15),
        F("couch", 4.7, 1.0, 5.6, 3.6),
        F("coffee_table", 6.2, 1.6, 7.0, 3.0),
        F("tv_stand", 8.5, 1.0, 8.94, 3.6),
        F("armchair", 4.9, 4.4, 5.8, 5.3),
        F("piano", 0.3, 5.0, 1.8, 5.7),
        F("plant", 8.3, 9.3, 8.88, 9.88),
        F("bed", 11.6, 0.12, 13.2, 2.3, top=(96, 120, 190)),
        F("nightstand", 11.05, 0.12, 11.5, 0.55), F("nightstand", 13.3, 0.12, 13.75, 0.55),
        F("wardrobe", 13.28, 3.0, 13.88, 5.2),
        F("dresser", 9.06, 4.6, 10.4, 5.2),
        F("cabinet", 9.1, 9.45, 10.4, 9.88),
        F("bathtub", 12.2, 9.1, 13.88, 9.88),
        F("vanity", 13.38, 6.3, 13.88, 7.3),
        F("toilet", 11.62, 9.3, 12.1, 9.88),
    ),
    description="14 x 10 m: open-plan loft with kitchen and study, bedroom, hall, bathroom",
))

# Apartment2, 11 x 13 m: rooms on both sides of a central north-south corridor.
_add(Apartment(
    "Apartment2", (11.0, 13.0),
    walls=tuple(outer_walls(11.0, 13.0)
                + vwall(4.5, WALL, 13.0 - WALL, doors=[(2.0, 3.0), (7.0, 8.0), (11.0, 12.0)])
                + vwall(6.5, WALL, 13.0 - WALL, doors=[(1.5, 2.5), (5.5, 6.5), (10.2, 11.2)])
                + hwall(4.5, WALL, 4.44, doors=[])
                + hwall(9.8, WALL, 4.44, doors=[])
                + hwall(4.0, 6.56, 11.0 - WALL)
                + hwall(8.6, 6.56, 11.0 - WALL)),
    rooms=(
        room((0, 0, 11, 13), "slate", "grey", "corridor"),
        room((0, 0, 4.5, 4.5), "carpet_blue", "sky", "bedroom"),
        room((0, 4.5, 4.5, 9.8), "wood", "cream", "living"),
        room((0, 9.8, 4.5, 13), "bath", "white_tiles", "bathroom"),
        room((6.5, 0, 11, 4.0), "carpet_green", "sage", "study"),
        room((6.5, 4.0, 11, 8.6), "tile", "mustard", "kitchen"),
        room((6.5, 8.6, 11, 13), "carpet_rose", "lavender", "bedroom2"),
    ),
    furniture=(
        F("bed", 0.12, 0.8, 2.3, 2.4, top=(112, 170, 120)),
        F("nightstand", 0.12, 0.3, 0.6, 0.8),
        F("wardrobe", 2.9, 0.12, 4.3, 0.72),
        F("couch", 0.12, 5.4, 1.0, 8.0),
        F("coffee_table", 1.5, 6.0, 2.3, 7.4),
        F("tv_stand", 3.96, 5.2, 4.44, 7.0),
        F("bookshelf", 1.2, 9.34, 3.4, 9.74),
        F("armchair", 1.8, 4.62, 2.7, 5.5),
        F("bathtub", 0.12, 11.2, 1.8, 12.88),
        F("vanity", 2.4, 12.38, 3.6, 12.88),
        F("toilet", 3.9, 10.0, 4.44, 10.5),
        F("desk", 8.4, 0.12, 10.4, 0.8),
        F("chair", 9.1, 0.95, 9.55, 1.4),
        F("bookshelf", 10.48, 1.4, 10.88, 3.6),
        F("cabinet", 6.56, 3.0, 7.4, 3.94),
        F("counter", 10.25, 4.06, 10.88, 8.54),
        F("fridge", 8.8, 4.06, 9.5, 4.7),
        F("table", 7.6, 5.8, 9.0, 7.0),
        F("chair", 7.9, 5.25, 8.35, 5.7), F("chair", 8.2, 7.1, 8.65, 7.55),
        F("bed", 8.9, 10.4, 10.88, 12.4, top=(230, 196, 90)),
        F("dresser", 6.6, 12.3, 8.0, 12.88),
        F("plant", 5.05, 0.3, 5.95, 0.9),
        F("cabinet", 5.96, 8.6, 6.44, 9.8),
    ),
    description="11 x 13 m: central corridor; bedrooms, living room, bathroom, study, kitchen",
))

# Apartment3, 15 x 11 m: a large L of living spaces around a courtyard-like dining hall.
_add(Apartment(
    "Apartment3", (15.0, 11.0),
    walls=tuple(outer_walls(15.0, 11.0)
                + hwall(4.2, WALL, 5.5, doors=[(2.0, 3.0)])
                + vwall(5.5, WALL, 11.0 - WALL, doors=[(1.5, 2.5), (5.6, 6.6), (9.0, 10.0)])
                + vwall(10.0, WALL, 4.5, doors=[(2.0, 3.0)])
                + hwall(4.5, 9.94, 15.0 - WALL, doors=[(12.0, 13.0)])
                + hwall(7.6, 5.56, 9.0, doors=[(7.0, 8.0)])
                + vwall(9.0, 7.66, 11.0 - WALL)),
    rooms=(
        room((0, 0, 15, 11), "wood", "cream", "hall"),
        room((0, 0, 5.5, 4.2), "carpet_rose", "lavender", "bedroom"),
        room((0, 4.2, 5.5, 11), "oak", "sage", "living"),
        room((10, 0, 15, 4.5), "tile", "mustard", "kitchen"),
        room((5.5, 7.6, 9.0, 11), "bath", "white_tiles", "bathroom"),
        room((5.5, 0, 10, 7.6), "wood", "terracotta", "dining"),
    ),
    furniture=(
        F("bed", 0.12, 0.6, 2.3, 2.2, top=(220, 120, 70)),
        F("nightstand", 0.12, 2.35, 0.6, 2.8),
        F("wardrobe", 3.2, 0.12, 5.0, 0.72),
        F("dresser", 4.7, 2.8, 5.44, 3.9),
        F("couch", 0.6, 8.9, 3.4, 9.8),
        F("armchair", 3.8, 8.6, 4.7, 9.5),
        F("coffee_table", 1.4, 7.4, 2.8, 8.1),
        F("tv_stand", 1.0, 4.32, 3.4, 4.8),
        F("piano", 0.2, 5.6, 0.9, 7.1),
        F("plant", 4.8, 10.3, 5.4, 10.88),
        F("table", 6.8, 3.0, 8.8, 4.4),
        F("chair", 7.1, 2.45, 7.55, 2.9), F("chair", 8.0, 2.45, 8.45, 2.9),
        F("chair", 7.1, 4.5, 7.55, 4.95), F("chair", 8.0, 4.5, 8.45, 4.95),
        F("bookshelf", 9.5, 5.0, 9.9, 7.4),
        F("plant", 5.7, 0.2, 6.3, 0.8),
        F("counter", 10.5, 0.12, 14.88, 0.75),
        F("fridge", 14.18, 0.9, 14.88, 1.6),
        F("island", 11.4, 2.0, 13.6, 2.9),
        F("washer", 10.06, 3.7, 10.7, 4.44),
        F("bathtub", 5.56, 9.2, 7.2, 10.88),
        F("vanity", 8.44, 8.0, 8.94, 9.0),
        F("toilet", 7.8, 10.4, 8.3, 10.88),
        F("desk", 12.5, 10.2, 14.6, 10.88),
        F("chair", 13.3, 9.6, 13.75, 10.05),
        F("bookshelf", 14.48, 6.0, 14.88, 8.4),
        F("couch", 11.0, 6.3, 11.9, 8.6),
        F("cabinet", 10.2, 4.56, 11.4, 5.0),
    ),
    description="15 x 11 m: bedroom, living room, dining hall, kitchen, bathroom and a study corner",
))


def get_apartment(name: str) -> Apartment:
    """The apartment called ``name``; ``KeyError`` listing the known names otherwise."""
    try:
        return APARTMENTS[name]
    except KeyError:
        raise KeyError(f"unknown apartment {name!r}; known: {', '.join(sorted(APARTMENTS))}") from None


__all__ = [
    "APARTMENTS", "APARTMENT_ENV_KWARGS", "Apartment", "CEILING", "FLOORS", "FURNITURE", "Furniture", "WALL",
    "WALLS", "get_apartment", "hwall", "outer_walls", "vwall",
]
