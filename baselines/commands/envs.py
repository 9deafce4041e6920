"""``safe-mapf envs``: list the registered environment ids."""
from __future__ import annotations

import argparse
import json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("envs", help="list the registered environment ids", description=run.__doc__)
    p.add_argument("--json", action="store_true", help="print a JSON list instead of a table")
    p.set_defaults(func=run)


def env_rows() -> list:
    """One dict per registered id: id, map, world size, obs type, max steps, cost radius."""
    import safe_mapf_envs
    from safe_mapf_envs.scenario import resolve_layout

    rows = []
    for spec in safe_mapf_envs.ENV_SPECS:
        layout = resolve_layout(spec.layout)
        w, h = layout.size
        rows.append({
            "id": spec.id,
            "map": layout.name,
            "world": f"{w:g}x{h:g}",
            "obs": spec.obs_type,
            "max_steps": spec.max_episode_steps,
            "cost_radius": layout.cost_radius,
            "kind": "parallel" if "multi" in spec.entry_point else "single",
        })
    return rows


def run(args: argparse.Namespace) -> int:
    """Print the registered ids with their map, world size, observation type and step limit."""
    rows = env_rows()
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    cols = ["id", "map", "world", "obs", "max_steps", "cost_radius"]
    widths = {c: max(len(c), *(len(str(r[c])) for r in rows)) for c in cols}
    print("  ".join(c.ljust(widths[c]) for c in cols))
    print("  ".join("-" * widths[c] for c in cols))
    for r in rows:
        print("  ".join(str(r[c]).ljust(widths[c]) for c in cols))
    return 0
