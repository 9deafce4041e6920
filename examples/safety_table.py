"""The safety layer against no layer, count by count: arrivals, cost, contacts and the safety rate.

Reads folders of ``safe-mapf evaluate`` (with the safety layer, and with ``--safety off`` on the
same problems; several of each pool their runs, e.g. two seeds) and prints a Markdown table: CSR
(runs in which every agent arrived), ISR (agents that arrived), the mean largest cumulative cost
over all runs, contacts per run, the safety rate (agents that never touched another) and the
makespan; then why the agents touched, per agent count and layer
(:mod:`baselines.contact_anatomy`, from the rows' ``contact_reasons``).

Run: ``python examples/safety_table.py --on results/on_s1 results/on_s2 --off results/off_s1 results/off_s2``
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from baselines.contact_anatomy import CONTACT_REASONS, contact_summary
from baselines.output import read_rows


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--on", type=Path, nargs="+", required=True, help="evaluate folders with the safety layer")
    p.add_argument("--off", type=Path, nargs="+", required=True, help="evaluate folders with --safety off")
    args = p.parse_args(argv)
    rows = {}
    for name, folders in (("on", args.on), ("off", args.off)):
        rows[name] = []
        for folder in folders:
            path = folder / "runs.csv"
            if not path.is_file():
                raise SystemExit(f"{path}: no such file (an output folder of safe-mapf evaluate?)")
            rows[name] += read_rows(path)
    print("| agents | layer | CSR | ISR | mean largest cost | contacts per run | safety rate | makespan |")
    print("|---|---|---|---|---|---|---|---|")
    for k in sorted({r["agents"] for r in rows["on"]}):
        for name, runs in rows.items():
            rs = [r for r in runs if r["agents"] == k]
            if not rs:
                continue
            safe = [r["safety_rate"] for r in rs if r.get("safety_rate") not in (None, "")]
            rate = f"{np.mean(safe):.1%}" if safe else "n/a"  # rows of an earlier release lack it
            print(f"| {k} | {name} | {np.mean([r['success'] for r in rs]):.0%} | "
                  f"{np.mean([r['isr'] for r in rs]):.1%} | {np.mean([r['cost_max'] for r in rs]):.2f} | "
                  f"{np.mean([r['collisions'] for r in rs]):.1f} | {rate} | "
                  f"{np.mean([r['makespan'] for r in rs]):.0f} |")
    pooled = [{**r, "method": name, "difficulty": "all"} for name, runs in rows.items() for r in runs]
    summary = sorted(contact_summary(pooled), key=lambda c: (c["agents"], c["method"] == "off"))
    if summary:  # runs of an earlier release did not record the reasons
        print("\nWhy agents touched: contacts per reason over the runs that recorded them\n")
        print("| agents | layer | runs | contacts per run | " + " | ".join(CONTACT_REASONS) + " |")
        print("|---|---|---|---|" + "---|" * len(CONTACT_REASONS))
        for c in summary:
            print(f"| {c['agents']} | {c['method']} | {c['runs']} | {c['contacts'] / c['runs']:.1f} | "
                  + " | ".join(str(c[k]) for k in CONTACT_REASONS) + " |")


if __name__ == "__main__":
    raise SystemExit(main())
