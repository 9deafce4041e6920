"""Renderable 3D scenes made of floor-standing boxes, for the panorama raycaster.

A :class:`Scene` is the 2D layout of the collision world lifted into 3D: every obstacle box
gets a height and materials for its sides and top; walls reach the ceiling. The floor is
split into rooms, each with its own floor material and the material of the walls seen from
inside it, so two rooms with the same furniture still look different. Everything the
renderer needs per scene (box bounds, heights, a material table, floor and room rasters) is
precomputed once here.

Units are those of the layout (metres for apartments, grid units for 2D maps); a scene
carries its own camera height, ceiling height and sensor range in those units.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..checks import show

Box = Tuple[float, float, float, float]
Colour = Tuple[int, int, int]


@dataclass(frozen=True)
class Material:
    """A colour with a simple procedural texture.

    The texture is evaluated at surface coordinates ``(s, z)``: ``s`` runs along a side face
    (or is ``x`` on tops and floors) and ``z`` is the height (or ``y`` on tops and floors).
    With ``a = floor(s / stripe)`` and ``b = floor(z / band)``, the brightness is
    ``1 - stripe_contrast * (a odd) - band_contrast * (b odd) - checker * (a + b odd)``.

    Attributes:
        colour: base RGB colour.
        stripe: period of stripes along ``s`` (0: none).
        stripe_contrast: darkening of every other stripe.
        band: period of bands along ``z`` (0: none).
        band_contrast: darkening of every other band.
        checker: darkening of the odd cells of the checkerboard made by stripes and bands.
        skirting: height of a dark strip at the bottom of side faces (0: none).
    """

    colour: Colour
    stripe: float = 0.0
    stripe_contrast: float = 0.0
    band: float = 0.0
    band_contrast: float = 0.0
    checker: float = 0.0
    skirting: float = 0.0

    def row(self) -> List[float]:
        """The material as one row of the renderer's table (inverse periods, 0 for none)."""
        inv = lambda p: 0.0 if p <= 0 else 1.0 / p  # noqa: E731
        return [*map(float, self.colour), inv(self.stripe), self.stripe_contrast, inv(self.band),
                self.band_contrast, self.checker, self.skirting]


@dataclass(frozen=True)
class SceneBox:
    """A floor-standing box: its footprint, height and materials.

    Attributes:
        box: footprint ``(x0, y0, x1, y1)``.
        height: top of the box; at least the ceiling height means a wall.
        side: material of the four sides.
        top: material of the top face.
        room_coloured: if ``True`` the sides take the wall material of the room they face
            (used for walls, so a wall looks different from each side).
    """

    box: Box
    height: float
    side: Material
    top: Material
    room_coloured: bool = False


@dataclass(frozen=True)
class Room:
    """A rectangle of floor with its floor material and the material of walls seen from it."""

    box: Box
    floor: Material
    walls: Material
    name: str = ""


#: The material table has these columns: r, g, b, 1/stripe, stripe contrast, 1/band,
#: band contrast, checker contrast, skirting height.
MATERIAL_COLUMNS = 9


def _texture(mat, s: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Brightness factor of materials at surface coordinates ``s, z``.

    ``mat`` holds the material columns (see :meth:`Material.row`): an array whose last axis
    has the 9 columns, or a sequence of 9 arrays of the shape of ``s``.
    """
    cols = [mat[..., i] for i in range(MATERIAL_COLUMNS)] if isinstance(mat, np.ndarray) else mat
    # the integer parts decide the parity; truncation mirrors the pattern at 0, which is harmless
    a = (s * cols[3]).astype(np.int32)
    b = (z * cols[5]).astype(np.int32)
    out = 1.0 - cols[4] * (a & 1) - cols[6] * (b & 1) - cols[7] * ((a + b) & 1)
    return out.astype(np.float32, copy=False)


class Scene:
    """Boxes, rooms, ceiling and camera defaults of one renderable world.

    Args:
        size: world extent ``(width, height)``.
        boxes: the obstacles; the four outer boundary walls are added automatically.
        rooms: floor regions with their floor and wall materials; where rooms overlap the
            later one wins, and floor outside every room belongs to ``default_room``.
        default_room: materials of floor not covered by ``rooms`` (its box is ignored).
        ceiling_height: height of the ceiling and of walls.
        camera_height: default eye height of the sensor (below the ceiling).
        max_range: default sensor range; depth is scaled to ``[0, 255]`` over it.
        agent_height: height of agents drawn as cylinders in multi-agent panoramas.
        ceiling_colour: RGB of the ceiling.
        raster_resolution: cell size of the floor and room rasters (default: 1/256 of the
            longer side).
        name: label for error messages.
    """

    def __init__(
        self,
        size: Tuple[float, float],
        boxes: Sequence[SceneBox],
        rooms: Sequence[Room] = (),
        default_room: Optional[Room] = None,
        *,
        ceiling_height: float,
        camera_height: float,
        max_range: float,
        agent_height: float,
        ceiling_colour: Colour = (238, 238, 232),
        raster_resolution: Optional[float] = None,
        name: str = "scene",
    ) -> None:
        w, h = float(size[0]), float(size[1])
        if not (np.isfinite(w) and np.isfinite(h) and w > 0 and h > 0):
            raise ValueError(f"scene size must be two positive numbers, got {show(size)}")
        for what, val in (("ceiling_height", ceiling_height), ("max_range", max_range), ("agent_height", agent_height)):
            if not np.isfinite(val) or val <= 0:
                raise ValueError(f"{what} must be a positive number, got {show(val)}")
        if not (0 < camera_height < ceiling_height):
            raise ValueError(
                f"camera_height must lie strictly between 0 and the ceiling height {ceiling_height:g}, "
                f"got {show(camera_height)}"
            )
        self.name = name
        self.size = (w, h)
        self.ceiling_height = float(ceiling_height)
        self.camera_height = float(camera_height)
        self.max_range = float(max_range)
        self.agent_height = float(agent_height)
        self.ceiling_colour = np.asarray(ceiling_colour, dtype=np.float32)
        if default_room is None:
            default_room = Room((0.0, 0.0, w, h), Material((190, 180, 160)), Material((225, 220, 205)))
        self.rooms: List[Room] = [default_room] + list(rooms)

        # the outer boundary, as four walls just outside the world
        t = max(w, h)
        boundary = [(-t, -t, w + t, 0.0), (w, -t, w + t, h + t), (-t, h, w + t, h + t), (-t, -t, 0.0, h + t)]
        plain = Material((200, 200, 200))
        self.boxes: List[SceneBox] = list(boxes) + [
            SceneBox(b, self.ceiling_height, plain, plain, room_coloured=True) for b in boundary
        ]
        self.n_static = len(self.boxes)

        # per-box arrays
        arr = np.array([sb.box for sb in self.boxes], dtype=np.float64).reshape(-1, 4)
        if np.any(arr[:, 2] <= arr[:, 0]) or np.any(arr[:, 3] <= arr[:, 1]):
            bad = [sb.box for sb in self.boxes if sb.box[2] <= sb.box[0] or sb.box[3] <= sb.box[1]]
            raise ValueError(f"scene {name!r}: boxes must have x0 < x1 and y0 < y1, got {bad[:3]}")
        self.lo = arr[:, :2].astype(np.float32)
        self.hi = arr[:, 2:].astype(np.float32)
        heights = np.array([sb.height for sb in self.boxes], dtype=np.float64)
        if np.any(~np.isfinite(heights)) or np.any(heights <= 0):
            raise ValueError(f"scene {name!r}: box heights must be positive, got {heights[heights <= 0][:3]}")
        self.heights = np.minimum(heights, self.ceiling_height).astype(np.float32)
        self.is_wall = self.heights >= self.ceiling_height
        self.room_coloured = np.array([sb.room_coloured for sb in self.boxes], dtype=bool)

        # material table: per box a side and a top material, then per room its wall material
        rows: List[List[float]] = []
        index: Dict[Material, int] = {}

        def mat_id(m: Material) -> int:
            if m not in index:
                index[m] = len(rows)
                rows.append(m.row())
            return index[m]

        self.side_material = np.array([mat_id(sb.side) for sb in self.boxes], dtype=np.int32)
        self.top_material = np.array([mat_id(sb.top) for sb in self.boxes], dtype=np.int32)
        self.room_wall_material = np.array([mat_id(r.walls) for r in self.rooms], dtype=np.int32)
        self._material_rows = rows
        self._material_index = index
        self.materials = np.array(rows, dtype=np.float32).reshape(-1, MATERIAL_COLUMNS)

        # floor and room rasters
        res = float(raster_resolution) if raster_resolution else max(w, h) / 256.0
        self.raster_resolution = res
        nx, ny = int(np.ceil(w / res)), int(np.ceil(h / res))
        xs = (np.arange(nx) + 0.5) * res
        ys = (np.arange(ny) + 0.5) * res
        gx, gy = np.meshgrid(xs, ys)
        room_id = np.zeros((ny, nx), dtype=np.int32)
        for i, r in enumerate(self.rooms[1:], start=1):
            x0, y0, x1, y1 = r.box
            room_id[(gx >= x0) & (gx < x1) & (gy >= y0) & (gy < y1)] = i
        self.room_raster = room_id
        floor_mats = np.array([r.floor.row() for r in self.rooms], dtype=np.float32)[room_id]
        tex = _texture(floor_mats, gx.astype(np.float32), gy.astype(np.float32))
        self.floor_raster = (floor_mats[..., :3] * tex[..., None]).astype(np.float32)
        self._cache: Dict[Any, Any] = {}

    def material_id(self, material: Material) -> int:
        """Row of ``material`` in the table, appending it if new (used for agents' materials)."""
        if material not in self._material_index:
            self._material_index[material] = len(self._material_rows)
            self._material_rows.append(material.row())
            self.materials = np.array(self._material_rows, dtype=np.float32)
        return self._material_index[material]

    def room_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Index into :attr:`rooms` of the room containing each point."""
        res = self.raster_resolution
        ny, nx = self.room_raster.shape
        ix = np.clip((x * (1.0 / res)).astype(np.int32), 0, nx - 1)
        iy = np.clip((y * (1.0 / res)).astype(np.int32), 0, ny - 1)
        return self.room_raster[iy, ix]

    def floor_colour(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Textured floor RGB (float) at each point, shape ``x.shape + (3,)``."""
        res = self.raster_resolution
        ny, nx = self.room_raster.shape
        ix = np.clip((x * (1.0 / res)).astype(np.int32), 0, nx - 1)
        iy = np.clip((y * (1.0 / res)).astype(np.int32), 0, ny - 1)
        return np.take(self.floor_raster.reshape(-1, 3), iy * nx + ix, axis=0).reshape(np.shape(x) + (3,))

    def top_down(self, pixels_per_unit: float = 40.0) -> np.ndarray:
        """A plan view, ``uint8`` RGB: textured floors, box tops shaded by height, walls dark.

        Pixel ``(i, j)`` shows the world point ``((j + 0.5) / ppu, (i + 0.5) / ppu)``.
        """
        w, h = self.size
        ppu = float(pixels_per_unit)
        nx, ny = int(round(w * ppu)), int(round(h * ppu))
        xs = ((np.arange(nx) + 0.5) / ppu).astype(np.float32)
        ys = ((np.arange(ny) + 0.5) / ppu).astype(np.float32)
        gx, gy = np.meshgrid(xs, ys)
        img = self.floor_colour(gx, gy)
        # draw lower boxes first so taller ones (walls) stay on top
        for b in np.argsort(self.heights[: self.n_static - 4], kind="stable"):
            x0, y0 = self.lo[b]
            x1, y1 = self.hi[b]
            j0, j1 = int(round(x0 * ppu)), int(round(x1 * ppu))
            i0, i1 = int(round(y0 * ppu)), int(round(y1 * ppu))
            j0, i0 = max(j0, 0), max(i0, 0)
            if j1 <= j0 or i1 <= i0:
                continue
            if self.is_wall[b]:
                img[i0:i1, j0:j1] = (70.0, 70.0, 74.0)
                continue
            mat = self.materials[self.top_material[b]]
            tex = _texture(mat, gx[i0:i1, j0:j1], gy[i0:i1, j0:j1])
            col = mat[:3] * tex[..., None]
            img[i0:i1, j0:j1] = col
            # a dark outline (3 cm) so neighbouring pieces stay distinct
            edge = max(1, int(round(0.03 * ppu)))
            img[i0:i0 + edge, j0:j1] *= 0.55
            img[i1 - edge:i1, j0:j1] *= 0.55
            img[i0:i1, j0:j0 + edge] *= 0.55
            img[i0:i1, j1 - edge:j1] *= 0.55
        return np.clip(img, 0, 255).astype(np.uint8)


# ---------------------------------------------------------------------------------------
# scenes for layouts without their own appearance (the 2D occupancy-grid maps)

#: Wall materials of the zones of a grid map (distinct hues, vertical stripes).
GRID_WALLS = [
    Material((196, 92, 74), stripe=0.5, stripe_contrast=0.12, skirting=0.06),
    Material((70, 130, 190), stripe=0.5, stripe_contrast=0.12, skirting=0.06),
    Material((92, 168, 96), stripe=0.5, stripe_contrast=0.12, skirting=0.06),
    Material((214, 170, 64), stripe=0.5, stripe_contrast=0.12, skirting=0.06),
    Material((150, 100, 180), stripe=0.5, stripe_contrast=0.12, skirting=0.06),
    Material((60, 170, 170), stripe=0.5, stripe_contrast=0.12, skirting=0.06),
    Material((210, 120, 160), stripe=0.5, stripe_contrast=0.12, skirting=0.06),
    Material((140, 140, 90), stripe=0.5, stripe_contrast=0.12, skirting=0.06),
    Material((120, 110, 220), stripe=0.5, stripe_contrast=0.12, skirting=0.06),
]

#: Floor colours of the zones of a grid map (pale, checkered by grid cell).
GRID_FLOORS = [
    (205, 190, 170), (175, 195, 205), (190, 205, 175), (215, 205, 160), (195, 180, 205),
    (170, 205, 200), (215, 185, 195), (200, 200, 185), (185, 185, 215),
]


def _scaled(m: Material, unit: float) -> Material:
    return Material(m.colour, m.stripe * unit, m.stripe_contrast, m.band * unit, m.band_contrast,
                    m.checker, m.skirting * unit)


def grid_scene(layout, zones: int = 3) -> Scene:
    """A scene for a layout whose boxes are all walls (e.g. a :class:`~safe_mapf_envs.maps.GridMap`).

    One grid cell (``layout.resize_factor`` units, 1 if absent) plays the part of one metre
    horizontally and walls are 2.5 cells high, with the camera at 1.2 cells: a corridor one
    cell wide looks like a narrow hallway. The world is tiled into ``zones x zones`` zones with
    their own floor and wall colours, so different places look different.
    """
    unit = float(getattr(layout, "resize_factor", 1.0))
    w, h = (float(s) for s in layout.size)
    rooms = []
    k = 0
    for zi in range(zones):
        for zj in range(zones):
            box = (zj * w / zones, zi * h / zones, (zj + 1) * w / zones, (zi + 1) * h / zones)
            floor = Material(GRID_FLOORS[k % len(GRID_FLOORS)], stripe=unit, band=unit, checker=0.08)
            rooms.append(Room(box, floor, _scaled(GRID_WALLS[k % len(GRID_WALLS)], unit), name=f"zone{k}"))
            k += 1
    wall = Material((128, 128, 128))
    boxes = [
        SceneBox((float(x0), float(y0), float(x1), float(y1)), 1e9, wall, wall, room_coloured=True)
        for x0, y0, x1, y1 in layout.boxes()
    ]
    return Scene(
        (w, h), boxes, rooms,
        ceiling_height=2.5 * unit, camera_height=1.2 * unit, max_range=float(np.hypot(w, h)),
        agent_height=0.9 * unit, raster_resolution=unit / 8.0, name=getattr(layout, "name", "grid"),
    )


def scene_for_layout(layout) -> Scene:
    """The renderable scene of a layout: its own ``scene()`` if it has one, else :func:`grid_scene`."""
    make = getattr(layout, "scene", None)
    if callable(make):
        scene = make()
        if not isinstance(scene, Scene):
            raise TypeError(
                f"layout {getattr(layout, 'name', layout)!r}: scene() must return a Scene, got {type(scene)}"
            )
        return scene
    return grid_scene(layout)


__all__ = ["GRID_FLOORS", "GRID_WALLS", "Material", "Room", "Scene", "SceneBox", "grid_scene", "scene_for_layout"]
