"""The paper's Tables I (2D navigation) and II (visual navigation), as printed in "Safe Multi-Agent
Navigation guided by Goal-Conditioned Safe Reinforcement Learning": per (scene,) difficulty and
agent count, the cumulative cost mean, its standard deviation and the success rate of each
method (``None``: not applicable, the paper runs the policies without search on single agents
only).

Table I's text names CentralObstacle; the authors' published code made it on CenterDot
(``SafeCenterDot-v0`` here), with the conventions of :mod:`baselines.paper_protocol`.

Its scenes are ReplicaCAD apartments in Habitat; ours are different apartments of our own, so the
numbers are set side by side for scale, not as a like-for-like comparison.
"""
from __future__ import annotations

from typing import Dict, Optional, Tuple

Cell = Optional[Tuple[float, float, float]]

#: the paper's method columns of both tables, in order, by our method names
TABLE1_METHODS = ("unconstrained_policy", "sorb", "constrained_policy", "ours")

#: (difficulty, agents) -> (mean, std, success rate) per method of TABLE1_METHODS
TABLE1: Dict[Tuple[str, int], Tuple[Cell, Cell, Cell, Cell]] = {
    ("easy", 1): ((0.46, 1.05, 1.0), (1.38, 2.62, 1.0), (0.47, 1.07, 1.0), (0.49, 1.06, 1.0)),
    ("easy", 5): (None, (6.39, 4.66, 1.0), None, (1.68, 1.21, 1.0)),
    ("easy", 10): (None, (8.69, 4.05, 1.0), None, (2.24, 1.03, 1.0)),
    ("easy", 20): (None, (10.51, 3.57, 1.0), None, (2.72, 0.80, 1.0)),
    ("medium", 1): ((1.58, 2.03, 1.0), (2.30, 3.02, 1.0), (1.58, 2.01, 1.0), (1.59, 1.99, 1.0)),
    ("medium", 5): (None, (5.12, 3.65, 1.0), None, (3.09, 1.50, 1.0)),
    ("medium", 10): (None, (7.27, 3.66, 0.98), None, (4.11, 1.48, 0.98)),
    ("medium", 20): (None, (8.73, 3.73, 0.98), None, (4.78, 1.33, 0.98)),
    ("hard", 1): ((3.98, 4.40, 1.0), (4.05, 4.19, 1.0), (4.19, 4.23, 1.0), (3.09, 3.87, 1.0)),
    ("hard", 5): (None, (8.58, 3.79, 1.0), None, (6.01, 1.96, 1.0)),
    ("hard", 10): (None, (10.77, 3.51, 1.0), None, (7.24, 1.52, 1.0)),
    ("hard", 20): (None, (11.96, 3.31, 1.0), None, (8.36, 1.58, 1.0)),
}

#: Table II's method columns (the same as Table I's)
TABLE2_METHODS = TABLE1_METHODS

#: the paper's four scenes, in its order (set beside SafeApartment0-v0 ... SafeApartment3-v0)
TABLE2_SCENES = ("SC2 Staging 08", "SC3 Staging 05", "SC3 Staging 11", "SC3 Staging 15")

#: (scene, difficulty, agents) -> (mean, std, success rate) per method of TABLE2_METHODS
TABLE2: Dict[Tuple[str, str, int], Tuple[Cell, Cell, Cell, Cell]] = {
    ('SC2 Staging 08', 'easy', 1): ((3.16, 9.4, 1.0), (2.14, 2.22, 0.98), (1.85, 1.8, 1.0), (1.28, 1.69, 1.0)),
    ('SC2 Staging 08', 'easy', 5): (None, (4.32, 2.29, 0.98), None, (3.35, 1.48, 1.0)),
    ('SC2 Staging 08', 'easy', 10): (None, (5.36, 2.6, 0.96), None, (4.02, 1.15, 1.0)),
    ('SC2 Staging 08', 'medium', 1): ((4.98, 3.46, 0.98), (5.15, 3.32, 0.98), (4.77, 3.25, 1.0), (3.35, 3.23, 1.0)),
    ('SC2 Staging 08', 'medium', 5): (None, (9.74, 11.13, 0.9), None, (6.18, 1.64, 0.98)),
    ('SC2 Staging 08', 'medium', 10): (None, (14.23, 23.53, 0.84), None, (7.3, 1.69, 0.98)),
    ('SC2 Staging 08', 'hard', 1): ((13.41, 4.0, 0.96), (12.35, 5.1, 0.9), (10.43, 3.07, 1.0), (9.62, 3.66, 1.0)),
    ('SC2 Staging 08', 'hard', 5): (None, (21.23, 14.64, 0.84), None, (13.02, 2.38, 0.98)),
    ('SC2 Staging 08', 'hard', 10): (None, (27.37, 19.05, 0.62), None, (13.87, 2.17, 0.92)),
    ('SC3 Staging 05', 'easy', 1): ((1.87, 1.65, 0.98), (2.23, 1.85, 0.98), (1.8, 1.58, 1.0), (1.25, 1.6, 1.0)),
    ('SC3 Staging 05', 'easy', 5): (None, (3.71, 1.96, 0.98), None, (2.76, 1.36, 1.0)),
    ('SC3 Staging 05', 'easy', 10): (None, (4.2, 1.73, 0.98), None, (3.32, 1.11, 1.0)),
    ('SC3 Staging 05', 'medium', 1): ((5.06, 3.27, 1.0), (4.87, 3.15, 1.0), (4.38, 2.91, 1.0), (2.66, 2.32, 1.0)),
    ('SC3 Staging 05', 'medium', 5): (None, (7.58, 2.16, 0.98), None, (5.88, 1.38, 1.0)),
    ('SC3 Staging 05', 'medium', 10): (None, (8.83, 1.75, 0.98), None, (7.28, 1.53, 0.96)),
    ('SC3 Staging 05', 'hard', 1): ((14.86, 4.9, 0.98), (13.16, 4.24, 1.0), (8.59, 2.21, 0.98), (6.47, 3.3, 0.98)),
    ('SC3 Staging 05', 'hard', 5): (None, (17.79, 2.68, 0.96), None, (15.1, 2.19, 0.96)),
    ('SC3 Staging 05', 'hard', 10): (None, (19.56, 2.66, 0.94), None, (16.71, 2.28, 0.94)),
    ('SC3 Staging 11', 'easy', 1): ((1.2, 1.56, 1.0), (1.27, 1.35, 1.0), (1.2, 1.55, 1.0), (0.78, 1.12, 1.0)),
    ('SC3 Staging 11', 'easy', 5): (None, (2.32, 1.11, 1.0), None, (1.88, 0.9, 1.0)),
    ('SC3 Staging 11', 'easy', 10): (None, (3.0, 1.07, 1.0), None, (2.54, 1.15, 1.0)),
    ('SC3 Staging 11', 'medium', 1): ((3.66, 2.95, 0.98), (4.19, 3.23, 0.98), (3.4, 2.83, 0.98), (1.95, 2.24, 1.0)),
    ('SC3 Staging 11', 'medium', 5): (None, (8.33, 2.37, 0.98), None, (5.93, 2.4, 0.96)),
    ('SC3 Staging 11', 'medium', 10): (None, (10.23, 2.27, 0.96), None, (8.13, 2.18, 0.94)),
    ('SC3 Staging 11', 'hard', 1): ((16.41, 6.5, 1.0), (14.75, 5.43, 1.0), (11.59, 3.6, 1.0), (10.93, 3.94, 1.0)),
    ('SC3 Staging 11', 'hard', 5): (None, (18.67, 2.51, 0.96), None, (15.78, 2.16, 0.98)),
    ('SC3 Staging 11', 'hard', 10): (None, (20.37, 2.41, 0.92), None, (16.94, 1.66, 0.92)),
    ('SC3 Staging 15', 'easy', 1): ((1.9, 1.76, 1.0), (2.08, 1.73, 1.0), (1.87, 1.77, 1.0), (1.47, 1.39, 1.0)),
    ('SC3 Staging 15', 'easy', 5): (None, (3.82, 3.53, 1.0), None, (2.77, 1.32, 1.0)),
    ('SC3 Staging 15', 'easy', 10): (None, (4.83, 3.68, 1.0), None, (3.63, 1.39, 1.0)),
    ('SC3 Staging 15', 'medium', 1): ((3.76, 3.42, 1.0), (4.16, 2.79, 1.0), (3.23, 2.51, 1.0), (2.01, 1.75, 1.0)),
    ('SC3 Staging 15', 'medium', 5): (None, (6.7, 1.81, 1.0), None, (5.18, 2.32, 1.0)),
    ('SC3 Staging 15', 'medium', 10): (None, (10.21, 14.89, 0.96), None, (6.66, 1.59, 1.0)),
    ('SC3 Staging 15', 'hard', 1): ((13.83, 4.35, 1.0), (14.37, 11.06, 0.98), (9.75, 2.74, 1.0), (7.61, 3.1, 1.0)),
    ('SC3 Staging 15', 'hard', 5): (None, (19.23, 11.03, 0.88), None, (11.63, 2.7, 1.0)),
    ('SC3 Staging 15', 'hard', 10): (None, (19.7, 3.73, 0.84), None, (12.85, 2.12, 0.98)),
}

__all__ = ["TABLE1", "TABLE1_METHODS", "TABLE2", "TABLE2_METHODS", "TABLE2_SCENES"]
