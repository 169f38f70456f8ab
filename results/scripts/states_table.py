"""Print the states of shield models as Markdown: centre, spread, visits, entries (where the
model counted them), failures by criterion and flag, and how many collisions were recognised
in states that are not flagged now.

    python results/scripts/states_table.py URL/models/NAME     a model on a shield service
    python results/scripts/states_table.py OUT                 every model in OUT/models/

OUT/models/ holds the model of each shielded run where it finished or stopped, gzipped, as
`client run` keeps them.
"""

import gzip
import json
import sys
from pathlib import Path
from typing import Any

import httpx

from app.core import Shield
from app.service import codec


def view(model: dict[str, Any]) -> dict[str, Any]:
    """What GET /models/{name} shows of an exact model, computed here (without entries where
    the model was stored before they were counted)."""
    shield = Shield.from_snapshot(codec.from_json(model))
    states = codec.readable(shield, "none")["states"]
    if "entries" not in model["flags"]:
        for s in states:
            del s["entries"]
    return {
        "n_states": shield.n_states,
        "episodes": shield.counters.episodes,
        "config": shield.config.to_dict(),
        "states": states,
    }


def collisions(states: list[dict[str, Any]], unflagged: bool = False) -> int:
    """The collisions recognised in these states (only those not flagged now)."""
    return sum(s["failures"]["collision"] for s in states if not (unflagged and s["flag"]))


def table(snapshot: dict[str, Any]) -> str:
    """One model's states; the entries column only where the model counted them."""
    entries = "entries" in snapshot["states"][0] if snapshot["states"] else False
    lines = [
        f"{snapshot['n_states']} states after {snapshot['episodes']} episodes",
        "",
        "| state | v_ego (m/s) | headway (m) | v_lead (m/s) | spread | visits | "
        + ("entries | " if entries else "")
        + "collisions | large distances | flag |",
        "|---:|---:|---:|---:|---:|---:|" + ("---:|" if entries else "") + "---:|---:|---|",
    ]
    for s in snapshot["states"]:
        v_ego, headway, v_lead = s["centre"]
        f = s["failures"]
        lines.append(
            f"| {s['index']} | {v_ego:.1f} | {headway:.1f} | {v_lead:.1f} "
            f"| {s['spread']:.3f} | {s['visits']} | "
            + (f"{s['entries']} | " if entries else "")
            + f"{f['collision']} | {f['large_distance']} | {s['flag'] or '-'} |"
        )
    states = snapshot["states"]
    reviser = snapshot["config"]["reviser"]
    rate = reviser.get("flag_min_rate")
    per = reviser.get("flag_rate_per", "recognition")
    lines += [
        "",
        f"{collisions(states, unflagged=True)} of {collisions(states)} collisions "
        f"were recognised in states not "
        f"flagged now (flags: {reviser['flags']}"
        + (f", min rate {rate}" if rate is not None else "")
        + (f" per {per}" if per != "recognition" else "")
        + ")",
    ]
    return "\n".join(lines) + "\n"


def main(target: str) -> None:
    if target.startswith("http"):
        snapshot = httpx.get(target, params={"tpm": "none"}, timeout=30).raise_for_status().json()
        sys.stdout.write(table(snapshot))
        return
    out = Path(target)
    summary = [
        "| model | episodes | states | flagged collision / large distance | collisions "
        "| of them in states not flagged now |",
        "|---|---:|---:|---|---:|---:|",
    ]
    parts = []
    for path in sorted((out / "models").glob("*.json.gz")):
        name = path.name.removesuffix(".json.gz")
        snapshot = view(json.loads(gzip.decompress(path.read_bytes()))["exact"])
        states = snapshot["states"]
        flagged = [sum(s["flag"] == c for s in states) for c in ("collision", "large_distance")]
        summary.append(
            f"| {name} | {snapshot['episodes']} | {len(states)} "
            f"| {flagged[0]} / {flagged[1]} | {collisions(states)} "
            f"| {collisions(states, unflagged=True)} |"
        )
        parts.append(f"### {name}\n\n{table(snapshot)}")
    sys.stdout.write("\n".join(["\n".join(summary) + "\n", *parts]))


if __name__ == "__main__":
    main(sys.argv[1])
