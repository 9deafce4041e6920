"""A batched numpy raycaster: four cardinal first-person views (RGB + depth) per agent.

Each view is a pinhole camera with a square image and a horizontal and vertical field of view
``fov``. The 2D ray of image column ``c`` is ``forward + u_c * right``, so its parameter ``t``
is the planar depth along the view axis, and the 3D ray of row ``r`` has height
``camera_height + v_r * t``.

Everything stands on the floor, which makes each column a skyline: sorted by the distance
``t_in`` at which its 2D ray enters them, the boxes (and agent cylinders) of a column cover
rows from ``v = -camera_height / t_in`` (where the box meets the floor) up to its top edge
``top = max((h - camera_height) / t_in, (h - camera_height) / t_out)`` (front face, or the far
edge of its top face when it is lower than the camera). A row ``v`` shows the first box whose
running maximum of ``top`` reaches ``v``, provided the row is not below where that box meets
the floor (then the floor in front of it shows); rows above every box show the ceiling. One
``searchsorted`` turns the running maxima into row counts, and a histogram of those counts,
accumulated down the rows, gives every pixel its box.

All agents, views, columns and boxes are processed together with no Python loop over agents,
rays or boxes. Walls are full height, so only the nearest wall of a column and the lower boxes
in front of it can be seen: after the 2D slab intersection each column keeps just those
candidates (typically 2 to 8). Colours come from a per-material table of ready-made texture
variants; depth is planar.
"""
from __future__ import annotations

from typing import Optional, Tuple

import numpy as np

from ..checks import show
from ..rendering import PALETTE
from .scene import Material, Scene

#: View order of the panorama: north (-y, up in top-down images), east (+x), south, west.
VIEW_NAMES = ("north", "east", "south", "west")
_FORWARD = np.array([(0.0, -1.0), (1.0, 0.0), (0.0, 1.0), (-1.0, 0.0)])
_RIGHT = np.array([(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)])
#: Direction the light comes from (for face shading), in world (x, y).
_LIGHT = np.array([0.6, -0.8])
_INF = np.float32(np.inf)


def _settle_allocator() -> None:
    """Let the C allocator keep render temporaries on the heap.

    glibc serves blocks above a dynamic threshold (initially 128 KiB) with fresh ``mmap``
    pages, so each of the few dozen numpy temporaries of a batched render (hundreds of KiB)
    would cost new page faults, more time than the rendering itself. Freeing one larger
    mapped block raises that threshold for the rest of the process (glibc's documented
    dynamic behaviour, which any process that once freed a big array already has), after
    which the temporaries are reused from the heap. Elsewhere this does nothing.
    """
    global _ALLOCATOR_SETTLED
    if not _ALLOCATOR_SETTLED:
        block = np.empty(8 << 20, dtype=np.uint8)  # 8 MiB
        del block
        _ALLOCATOR_SETTLED = True


_ALLOCATOR_SETTLED = False


def _agent_materials(i: int) -> Tuple[Material, Material]:
    r, g, b = (int(c) for c in PALETTE[i % len(PALETTE)])
    light = (int(min(255, r * 0.6 + 102)), int(min(255, g * 0.6 + 102)), int(min(255, b * 0.6 + 102)))
    return Material((r, g, b), band=0.25, band_contrast=0.25), Material(light)


class PanoramaSensor:
    """Renders RGB-D panoramas of a :class:`~safe_mapf_envs.sensors.scene.Scene`.

    Args:
        scene: the scene.
        image_size: height and width of each of the four views, in pixels.
        fov: horizontal and vertical field of view of each view, in degrees (0, 180).
        camera_height: eye height; default the scene's.
        max_range: sensor range; depth ``d`` is stored as ``round(255 * min(d / max_range, 1))``.
            Default the scene's.

    :meth:`render` returns ``uint8`` arrays of shape ``(N, 4, image_size, image_size, 4)``:
    per agent the views north, east, south, west; per view rows top to bottom and columns
    left to right; channels R, G, B, depth. Depth is planar (distance along the view axis).
    Surfaces are shaded by the direction they face and dimmed with distance (to 55% at
    ``max_range``), so the colour channels carry some depth too.
    """

    def __init__(
        self,
        scene: Scene,
        image_size: int = 32,
        fov: float = 90.0,
        camera_height: Optional[float] = None,
        max_range: Optional[float] = None,
    ) -> None:
        if int(image_size) != image_size or image_size < 2:
            raise ValueError(f"image_size must be an integer >= 2, got {show(image_size)}")
        if not np.isfinite(fov) or not (0 < fov < 180):
            raise ValueError(f"fov must be in (0, 180) degrees, got {show(fov)}")
        hc = scene.camera_height if camera_height is None else float(camera_height)
        if not (0 < hc < scene.ceiling_height):
            raise ValueError(
                f"camera_height must lie strictly between 0 and the ceiling height {scene.ceiling_height:g}, "
                f"got {show(hc)}"
            )
        rng = scene.max_range if max_range is None else float(max_range)
        if not np.isfinite(rng) or rng <= 0:
            raise ValueError(f"max_range must be a positive number, got {show(max_range)}")
        _settle_allocator()
        self.scene = scene
        self.image_size = n = int(image_size)
        self.fov = float(fov)
        self.camera_height = hc
        self.max_range = rng
        tan = np.tan(np.radians(self.fov) / 2.0)
        centres = ((np.arange(n) + 0.5) * 2.0 / n - 1.0) * tan
        # column rays: (4 * n, 2), view-major
        dirs = _FORWARD[:, None, :] + centres[None, :, None] * _RIGHT[:, None, :]
        self._dirs = dirs.reshape(-1, 2).astype(np.float32)
        d = self._dirs.astype(np.float64)
        safe = np.where(np.abs(d) < 1e-12, 1e-12, d)
        self._inv = (1.0 / safe).astype(np.float32)
        self._dir_sq = (d * d).sum(-1).astype(np.float32)
        # face shading per column: the face a ray enters through faces against the ray
        sx = 0.8 - 0.2 * np.sign(d[:, 0]) * _LIGHT[0]
        sy = 0.8 - 0.2 * np.sign(d[:, 1]) * _LIGHT[1]
        self._shade_x = sx.astype(np.float32)
        self._shade_y = sy.astype(np.float32)
        # rows: vertical slope of each row's ray (top row looks up)
        v = -centres
        self._v = v.astype(np.float32)
        with np.errstate(divide="ignore"):
            floor_t = np.where(v < 0, hc / -v, np.inf)
            ceil_t = np.where(v > 0, (scene.ceiling_height - hc) / v, np.inf)
        self._fc_t = np.minimum(floor_t, ceil_t).astype(np.float32)  # (n,)
        self._is_floor = v < 0
        self._n_up = int(np.sum(v >= 0))                      # upper rows see the ceiling, lower the floor
        self._inv_v = np.where(v != 0, 1.0 / np.where(v != 0, v, 1.0), np.inf).astype(np.float32)
        self._neg_v = (-v).astype(np.float32)               # increasing, for searchsorted
        # static per-scene arrays, walls first: per column, the slab planes a ray meets first
        # and last, and the boxes' heights and materials in that order
        order = np.argsort(~scene.is_wall, kind="stable")
        self._n_walls = int(scene.is_wall.sum())
        pos = self._inv > 0                                    # (C, 2)
        lo, hi = scene.lo[order], scene.hi[order]              # (B, 2)
        self._near = [np.where(pos[:, None, i], lo[None, :, i], hi[None, :, i]) for i in (0, 1)]  # (C, B)
        self._far = [np.where(pos[:, None, i], hi[None, :, i], lo[None, :, i]) for i in (0, 1)]
        self._height = scene.heights[order]
        self._side_mat = scene.side_material[order]
        self._top_mat = scene.top_material[order]
        self._room_col = scene.room_coloured[order]
        self._agent_mats = [
            [scene.material_id(m) for m in _agent_materials(i)] for i in range(len(PALETTE))
        ]
        # Every material as 16 ready-made colours, indexed by the bits (top face, odd stripe,
        # odd band, skirting), so a pixel's colour is one table row (see Material). Tops are lit
        # a little brighter than sides; no entry exceeds 255.
        m = scene.materials
        bits = (np.arange(16)[:, None] >> np.arange(3, -1, -1)[None, :]) & 1  # (16, 4)
        top, pa, pb, sk = (bits[:, i].astype(np.float32) for i in range(4))
        bright = (1.0 - m[:, None, 4] * pa - m[:, None, 6] * pb - m[:, None, 7] * ((pa + pb) % 2))
        bright = bright * (1.0 - 0.45 * sk) * (1.0 + 0.1 * top)
        palette = np.minimum(m[:, None, :3] * bright[..., None], 255.0).reshape(-1, 3)
        self._palette_cols = [np.ascontiguousarray(palette[:, i], dtype=np.float32) for i in range(3)]
        self._fog = (1.0 - 0.45 * np.arange(256) / 255.0).astype(np.float32)
        self._inv_stripe = np.ascontiguousarray(m[:, 3])
        self._inv_band = np.ascontiguousarray(m[:, 5])
        self._skirting = np.ascontiguousarray(m[:, 8])

    @property
    def shape(self) -> Tuple[int, int, int, int]:
        """Shape of one panorama: ``(4, image_size, image_size, 4)``."""
        return (4, self.image_size, self.image_size, 4)

    # ------------------------------------------------------------------------------------
    def render(
        self,
        positions: np.ndarray,
        agents: Optional[np.ndarray] = None,
        agent_radius: float = 0.0,
        self_index: Optional[np.ndarray] = None,
        agent_colours: Optional[np.ndarray] = None,
    ) -> np.ndarray:
        """Panoramas seen from ``positions``.

        Args:
            positions: camera positions, shape ``(N, 2)`` (or ``(2,)`` for one).
            agents: centres of agents drawn as cylinders of radius ``agent_radius`` and the
                scene's ``agent_height``, shape ``(M, 2)``; ``None`` for none.
            agent_radius: radius of those cylinders.
            self_index: for each camera, the index in ``agents`` of the agent carrying it
                (not drawn in its own view), or -1; default: none. A cylinder that contains
                the camera is never drawn either.
            agent_colours: colour index (into the top-down palette) of each agent; default
                ``arange(M)``.

        Returns:
            ``uint8`` array ``(N, 4, S, S, 4)`` (``(4, S, S, 4)`` for a single ``(2,)`` position).
        """
        p = np.asarray(positions, dtype=np.float64)
        single = p.shape == (2,)
        if not single and (p.ndim != 2 or p.shape[1] != 2 or p.shape[0] == 0):
            raise ValueError(f"positions must have shape (N, 2) with N >= 1, or (2,), got shape {p.shape}")
        p = p.reshape(-1, 2)
        if not np.all(np.isfinite(p)):
            raise ValueError(f"positions must be finite, got {show(positions)}")
        if agents is not None:
            agents = np.asarray(agents, dtype=np.float64)
            if agents.size and (agents.ndim != 2 or agents.shape[1] != 2 or not np.all(np.isfinite(agents))):
                raise ValueError(f"agents must be finite positions of shape (M, 2), got shape {agents.shape}")
            if agents.size and not (np.isfinite(agent_radius) and agent_radius > 0):
                raise ValueError(f"agent_radius must be a positive number to draw agents, got {show(agent_radius)}")
        out = self._render(p.astype(np.float32), agents, agent_radius, self_index, agent_colours)
        return out[0] if single else out

    def _render(self, p, agents, agent_radius, self_index, agent_colours) -> np.ndarray:
        sc = self.scene
        N = p.shape[0]
        S = self.image_size
        C = 4 * S
        NC = N * C
        W = self._n_walls
        dx, dy = self._dirs[:, 0], self._dirs[:, 1]
        hc = np.float32(self.camera_height)
        px = p[:, 0, None, None]
        py = p[:, 1, None, None]

        # ---- 2D slab intersection of every column ray with every box: (N, C, B), walls first
        ix = self._inv[None, :, 0, None]
        iy = self._inv[None, :, 1, None]
        tnx = (self._near[0][None] - px) * ix
        tny = (self._near[1][None] - py) * iy
        xface = tnx >= tny
        tin = np.maximum(np.maximum(tnx, tny), np.float32(1e-4))
        tout = np.minimum((self._far[0][None] - px) * ix, (self._far[1][None] - py) * iy)
        hit = tout > tin
        height, side_mat, top_mat, room_col = self._height, self._side_mat, self._top_mat, self._room_col

        # ---- agents as cylinders, appended after the boxes: (N, C, M)
        a = None
        if agents is not None and len(np.asarray(agents).reshape(-1, 2)) and agent_radius > 0:
            a = np.asarray(agents, dtype=np.float32).reshape(-1, 2)
            M = len(a)
            R = np.float32(agent_radius)
            ocx = (a[None, :, 0] - p[:, 0, None])[:, None, :]           # (N, 1, M)
            ocy = (a[None, :, 1] - p[:, 1, None])[:, None, :]
            b = ocx * dx[None, :, None] + ocy * dy[None, :, None]       # (N, C, M)
            qa = self._dir_sq[None, :, None]
            cc = ocx * ocx + ocy * ocy - R * R                          # < 0: camera inside
            disc = b * b - qa * cc
            root = np.sqrt(np.maximum(disc, 0))
            ctin = np.maximum((b - root) / qa, np.float32(1e-4))
            ctout = (b + root) / qa
            chit = (disc > 0) & (ctout > ctin) & (cc > 0)       # an agent never sees its own body
            if self_index is not None:
                si = np.asarray(self_index).reshape(-1)
                if si.shape != (N,):
                    raise ValueError(f"self_index must have one entry per camera ({N}), got shape {si.shape}")
                chit &= (si[:, None] != np.arange(M)[None, :])[:, None, :]
            cols = np.arange(M) if agent_colours is None else np.asarray(agent_colours).reshape(M)
            am = np.array(self._agent_mats, dtype=np.int32)[cols % len(PALETTE)]  # (M, 2)
            tin = np.concatenate([tin, ctin], -1)
            tout = np.concatenate([tout, ctout], -1)
            hit = np.concatenate([hit, chit], -1)
            xface = np.concatenate([xface, np.zeros(chit.shape, bool)], -1)
            height = np.concatenate([height, np.full(M, sc.agent_height, np.float32)])
            side_mat = np.concatenate([side_mat, am[:, 0]])
            top_mat = np.concatenate([top_mat, am[:, 1]])
            room_col = np.concatenate([room_col, np.zeros(M, bool)])

        # ---- candidates: the nearest wall, and the lower objects in front of it, nearest first
        tw = np.where(hit[..., :W], tin[..., :W], _INF)
        wj = tw.argmin(-1)[..., None]                        # (N, C, 1); boundary walls: always a hit
        t_wall = np.take_along_axis(tw, wj, -1)
        key = np.where(hit[..., W:] & (tin[..., W:] < t_wall), tin[..., W:], _INF)
        Kf = int(np.isfinite(key).sum(-1).max())
        sel_f = np.argsort(key, axis=-1)[..., :Kf]
        k_tin = np.concatenate([np.take_along_axis(key, sel_f, -1), t_wall], -1)  # inf: no candidate
        sel = np.concatenate([sel_f + W, wj], -1)             # (N, C, K) object ids
        K = Kf + 1
        k_tout = np.take_along_axis(tout, sel, -1)
        k_xf = np.take_along_axis(xface, sel, -1)
        valid = np.isfinite(k_tin)
        t_safe = np.where(valid, k_tin, np.float32(1.0))
        dh = height[sel] - hc
        top = np.where(valid, np.maximum(dh / t_safe, dh / k_tout), -_INF)
        # R[j]: rows strictly above the running top of candidates 0..j; a pixel in row r belongs
        # to the first candidate j with R[j] <= r, i.e. owner(r) = #{j : R[j] > r}
        Rj = np.searchsorted(self._neg_v, -np.maximum.accumulate(top, -1).ravel(), side="left")
        hist = np.bincount(Rj * NC + np.arange(NC).repeat(K), minlength=(S + 1) * NC)[: S * NC]
        owner = K - np.cumsum(hist.astype(np.int16).reshape(S, NC), 0, dtype=np.int16)  # (S, N*C); K: none
        pix = np.arange(0, NC * K, K)[None, :] + np.minimum(owner, K - 1)

        # ---- per pixel, in order (row, camera, column): depth and surface kind
        g_tin = np.take(t_safe, pix)
        g_dh = np.take(dh, pix)
        v = self._v[:, None]
        vt = v * g_tin
        is_obj = (owner < K) & (vt >= -hc)                   # not below where it meets the floor
        front = vt <= g_dh
        with np.errstate(divide="ignore", invalid="ignore"):
            d = np.where(front, g_tin, g_dh * self._inv_v[:, None])
        d = np.where(is_obj, d, self._fc_t[:, None])         # (S, N*C)
        z = hc + v * d

        # ---- per candidate: texture coordinate along the face, shading, side material
        hx = px + t_safe * dx[None, :, None]
        hy = py + t_safe * dy[None, :, None]
        k_s = np.where(k_xf, hy, hx)
        k_shade = np.where(k_xf, self._shade_x[None, :, None], self._shade_y[None, :, None])
        if a is not None:
            circ = sel >= sc.n_static
            ci = np.where(circ, sel - sc.n_static, 0)
            nx = (hx - a[ci, 0]) / R
            ny = (hy - a[ci, 1]) / R
            k_s = np.where(circ, np.arctan2(ny, nx) * R, k_s)
            k_shade = np.where(circ, 0.8 + 0.2 * (nx * np.float32(_LIGHT[0]) + ny * np.float32(_LIGHT[1])), k_shade)
        back = np.float32(sc.raster_resolution)
        room_mat = sc.room_wall_material[sc.room_at(hx - back * dx[None, :, None], hy - back * dy[None, :, None])]
        k_side = np.where(room_col[sel], room_mat, side_mat[sel])
        k_stripe = (k_s * self._inv_stripe[k_side]).astype(np.int32) & 1

        # ---- colours: palette index of every pixel as a side face (floor, ceiling and tops
        # are overwritten below), times shading and fog; side shading <= 0.96, fog <= 1
        idx = np.take((k_side * 16 + k_stripe * 4).astype(np.int32), pix)
        idx += (z * np.take(self._inv_band[k_side], pix)).astype(np.int32) & 1
        idx += idx & 1                                       # band parity weighs 2 in the palette
        idx += z < np.take(self._skirting[k_side], pix)
        light = np.take(k_shade, pix)
        depth8 = np.minimum(d * np.float32(255.0 / self.max_range) + 0.5, 255.0).astype(np.uint8)
        fog = np.take(self._fog, depth8)                     # 1 near, 0.55 at the sensor range
        ox = np.repeat(p[:, 0], C)
        oy = np.repeat(p[:, 1], C)
        cdx = np.tile(dx, N)
        cdy = np.tile(dy, N)
        ti = np.flatnonzero(is_obj & ~front)                 # tops: texture by (x, y)
        if len(ti):
            tc = ti % NC
            td = d.reshape(-1)[ti]
            tx = ox[tc] + td * cdx[tc]
            ty = oy[tc] + td * cdy[tc]
            tm = np.take(top_mat[sel], pix.reshape(-1)[ti])
            idx.reshape(-1)[ti] = (tm * 16 + 8 + ((tx * self._inv_stripe[tm]).astype(np.int32) & 1) * 4
                                   + ((ty * self._inv_band[tm]).astype(np.int32) & 1) * 2)
            light.reshape(-1)[ti] = 1.0
        light *= fog
        out = np.empty((3, S, NC), dtype=np.float32)         # planar R, G, B
        for ch in range(3):
            np.multiply(np.take(self._palette_cols[ch], idx), light, out=out[ch])

        # ---- floor (lower rows) and ceiling (upper rows)
        h = self._n_up
        bg = ~is_obj
        fi = np.flatnonzero(bg[h:])
        fc = fi % NC
        fd = d[h:].reshape(-1)[fi]
        fcol = sc.floor_colour(ox[fc] + fd * cdx[fc], oy[fc] + fd * cdy[fc]) * fog[h:].reshape(-1)[fi, None]
        ki = np.flatnonzero(bg[:h])
        ceil_fog = fog[:h].reshape(-1)[ki]
        for ch in range(3):
            out[ch, h:].reshape(-1)[fi] = fcol[:, ch]
            out[ch, :h].reshape(-1)[ki] = sc.ceiling_colour[ch] * ceil_fog

        rgb8 = out[:3].astype(np.uint8)                      # colours are <= 255: truncate
        img = np.empty((N, 4, S, S, 4), dtype=np.uint8)
        for ch, plane in enumerate((rgb8[0], rgb8[1], rgb8[2], depth8)):
            # (row, N, view, col) -> (N, view, row, col)
            img[..., ch] = plane.reshape(S, N, 4, S).transpose(1, 2, 0, 3)
        return img


def render_panoramas(
    scene: Scene,
    positions: np.ndarray,
    *,
    image_size: int = 32,
    fov: float = 90.0,
    camera_height: Optional[float] = None,
    max_range: Optional[float] = None,
    agents: Optional[np.ndarray] = None,
    agent_radius: float = 0.0,
    self_index: Optional[np.ndarray] = None,
) -> np.ndarray:
    """Panoramas of ``scene`` seen from ``positions (N, 2)``: ``uint8`` ``(N, 4, S, S, 4)``.

    A convenience over :class:`PanoramaSensor` that keeps one sensor per set of camera
    settings on the scene. See :meth:`PanoramaSensor.render` for the arguments.
    """
    key = ("panorama", int(image_size), float(fov), camera_height, max_range)
    sensor = scene._cache.get(key)
    if sensor is None:
        sensor = PanoramaSensor(scene, image_size, fov, camera_height, max_range)
        scene._cache[key] = sensor
    return sensor.render(positions, agents=agents, agent_radius=agent_radius, self_index=self_index)


__all__ = ["PanoramaSensor", "VIEW_NAMES", "render_panoramas"]
