"""Sensors: a batched numpy raycaster that renders RGB-D panoramas of box worlds.

The panoramas stand in for the four first-person views the paper "Safe Multi-Agent
Navigation guided by Goal-Conditioned Safe Reinforcement Learning" renders with a 3D simulator
(four 32x32 views, north, east, south and west, input dims ``(4, 32, 32, 4)``)::

    from safe_mapf_envs.maps import get_map
    from safe_mapf_envs.sensors import render_panoramas, scene_for_layout

    scene = scene_for_layout(get_map("Apartment0"))
    pano = render_panoramas(scene, [[2.0, 3.0], [5.0, 4.0]])  # uint8 (2, 4, 32, 32, 4): RGB + depth
"""
from .panorama import VIEW_NAMES, PanoramaSensor, render_panoramas
from .scene import Material, Room, Scene, SceneBox, grid_scene, scene_for_layout

__all__ = [
    "Material",
    "PanoramaSensor",
    "Room",
    "Scene",
    "SceneBox",
    "VIEW_NAMES",
    "grid_scene",
    "render_panoramas",
    "scene_for_layout",
]
