"""Notes under a result that cannot mean what its table suggests: a controller that put out no cell or
never left the base, fires out of the battery's range, a ratio of TTEs with no success behind it.

A note is one line; the tables print them under themselves, and a map suite lists them under its rows.
"""

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


def setting_notes(drones: DroneConfig, farthest: float) -> list[str]:
    """The notes of an evaluation's setting, under every controller's table: :func:`reach_note` for ``drones`` on a
    map whose farthest cell is ``farthest`` metres from its nearest base."""
    reach = reach_note(drones.battery_reach(), farthest)
    return [reach] if reach else []


def reach_note(reach: float | None, farthest: float) -> str | None:
    """A note where part of the map lies out of the battery's range: ``farthest`` is the distance in metres from
    the farthest cell to its nearest base (with one base in a corner, the opposite corner; with four, the
    middle). None without a battery or where every cell is in reach."""
    if reach is None or reach >= farthest:
        return None
    return (f"fires out of the battery's range: a full battery takes a drone at most {reach:.0f} m out and back, and "
            f"the farthest cell is {farthest:.0f} m from its nearest base; a fire farther away cannot be put out")


def ratio_is_meaningful(policy: dict, baseline: dict) -> bool:
    """A ratio of the two controllers' TTEs compares them only where both put out every fire at least once: with
    no success either TTE is the step limit (1.00 of 0 % against 0 %)."""
    return policy["success_rate"] > 0 and baseline["success_rate"] > 0
