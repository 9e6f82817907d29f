"""Notes under a result that cannot mean what its table suggests: a controller that put out no cell or
never left the base, fires out of the battery's range, a ratio of TTEs with no success behind it.

A note is one line; the tables print them under themselves, and a map suite lists them under its rows.
"""

import math

from roshan.config import DroneConfig


def controller_notes(summary: dict, who: str) -> list[str]:
    """What makes ``who``'s :func:`~roshan.runs.report.stats.summarize` result meaningless: it put out no cell in
    any episode, or (with a battery) drew no energy at all, so its drones never left the base."""
    notes = []
    energy = summary.get("energy_used")
    if energy is not None and energy["mean"] == 0:
        notes.append(f"{who} never left the base: its drones drew 0 J in every episode")
    fire = summary.get("extinguished")
    if fire is not None and fire["mean"] == 0:
        flights = summary.get("battery_swaps")
        home = (f" (its drones flew home {flights['mean'] * summary['episodes']:.0f} times)"
                if flights is not None and flights["mean"] else "")
        notes.append(f"{who} put out no cell in any of its {summary['episodes']} episodes{home}: its rates say "
                     "nothing about how it fights fire")
    return notes


def setting_notes(drones: DroneConfig, rows: int, cols: int, cell: float) -> list[str]:
    """The notes of an evaluation's setting, under every controller's table: :func:`reach_note` for ``drones`` on a
    map of ``rows`` x ``cols`` cells of ``cell`` metres."""
    reach = reach_note(drones.battery_reach(), rows, cols, cell)
    return [reach] if reach else []


def reach_note(reach: float | None, rows: int, cols: int, cell: float) -> str | None:
    """A note where part of the map lies out of the battery's range: the groundstation sits one cell inside a
    corner, so its opposite corner is the farthest a fire can be; None without a battery or where every cell is in
    reach."""
    if reach is None:
        return None
    far = cell * math.hypot(rows - 3, cols - 3)
    if reach >= far:
        return None
    return (f"fires out of the battery's range: a full battery takes a drone at most {reach:.0f} m out and back, and "
            f"the map's far corner is {far:.0f} m from the groundstation; a fire farther away cannot be put out")


def ratio_is_meaningful(policy: dict, baseline: dict) -> bool:
    """A ratio of the two controllers' TTEs compares them only where both put out every fire at least once: with
    no success either TTE is the step limit (1.00 of 0 % against 0 %)."""
    return policy["success_rate"] > 0 and baseline["success_rate"] > 0
