"""Print the states of a model on a shield service as Markdown: centre, spread, visits,
failures by criterion and flag. Usage: python results/states_table.py URL/models/NAME"""

import sys

import httpx

snapshot = httpx.get(sys.argv[1], params={"tpm": "none"}, timeout=30).raise_for_status().json()
lines = [
    f"{snapshot['n_states']} states after {snapshot['episodes']} episodes",
    "",
    "| state | v_ego (m/s) | headway (m) | v_lead (m/s) | spread | visits | collisions "
    "| large distances | flag |",
    "|---:|---:|---:|---:|---:|---:|---:|---:|---|",
]
for s in snapshot["states"]:
    v_ego, headway, v_lead = s["centre"]
    f = s["failures"]
    lines.append(f"| {s['index']} | {v_ego:.1f} | {headway:.1f} | {v_lead:.1f} "
                 f"| {s['spread']:.3f} | {s['visits']} | {f['collision']} "
                 f"| {f['large_distance']} | {s['flag'] or '-'} |")
sys.stdout.write("\n".join(lines) + "\n")
