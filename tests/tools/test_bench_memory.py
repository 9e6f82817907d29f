"""``roshan bench memory``'s plan: which maps, fire sizes and layouts it measures (the measurement itself,
``fire_footprint``, runs for minutes on the big maps; here it is replaced by a stand-in that records its calls)."""

import numpy as np

from roshan.maps import LandCoverMap
from roshan.tools import bench


def test_memory_report_measures_both_layouts_only_where_auto_would_pick_sparse(monkeypatch):
    small = LandCoverMap("small", np.full((4, 4), 2, np.int32), 10.0, None, None, None)
    big = LandCoverMap("big", np.full((400, 400), 2, np.int32), 10.0, None, None, None)  # 160,000 cells > 100,000
    monkeypatch.setattr(bench, "load_map", lambda name: small if name == "35x36_Woods" else big)
    monkeypatch.setattr(bench, "tiled_map", lambda: big)
    calls = []

    def footprint(land, pct, steps, layout, episodes):
        calls.append((land.name, pct, steps, layout, episodes))
        return {"map": land.name, "layout": layout}

    monkeypatch.setattr(bench, "fire_footprint", footprint)
    monkeypatch.setattr(bench, "format_footprint_row", lambda r: f"{r['map']} {r['layout']}")
    lines = []
    report = bench.memory_report(100, 0, 10, "cpu", 1, lines.append)
    assert calls[:2] == [("small", 0.015, 100, "auto", 3), ("small", 0.35, 10, "auto", 1)]
    assert calls[2:5] == [("big", 0.015, 100, "sparse", 3), ("big", 0.015, 100, "dense", 3),
                          ("big", 0.35, 10, "auto", 1)]
    assert len(calls) == 8 and len(report["runs"]) == 8 and "rss" not in report
    assert lines[0] == bench.FOOTPRINT_HEADER and lines[1:] == [f"{m} {layout}" for m, _, _, layout, _ in calls]
