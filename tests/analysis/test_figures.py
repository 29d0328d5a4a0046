"""The report's figures drawn from data a user's own settings shape."""

import numpy as np
import pandas as pd
import pytest
from matplotlib.image import imread

from hazardhunt.analysis import figures
from hazardhunt.analysis.figures import archive_heat_map


@pytest.mark.parametrize(
    "measures",
    [["bearing", "robot_speed", "emergency_stop"], ["route_share", "human_speed"], ["bearing"]],
)
def test_an_archive_is_drawn_over_whichever_measures_span_it(measures, tmp_path):
    rng = np.random.default_rng(0)
    archive = pd.DataFrame({name: rng.uniform(0.0, 1.0, 20) for name in measures})
    archive["objective"] = np.r_[rng.uniform(0.0, 1.0, 19), 150.0]  # one failure
    archive["index"] = np.arange(20)
    picture = archive_heat_map(archive, tmp_path / "archive.png", "my run")
    image = imread(picture)
    assert image.shape[0] > 200
    assert image.shape[1] > 400
    assert image[..., :3].std() > 0.1  # cells drawn, not a blank canvas


def test_failures_per_run_count_from_zero_and_an_empty_panel_says_it(tmp_path, monkeypatch):
    drawn = []
    monkeypatch.setattr(figures, "_save", lambda figure, path: drawn.append(figure) or path)
    runs = pd.DataFrame(
        {
            "scenario": ["crossing"] * 4,
            "field": ["none", "none", "sides", "sides"],
            "tester": ["random", "portfolio"] * 2,
            "seed": [0] * 4,
            "failures": [8, 45, 0, 0],
        }
    )
    figures.failures_bar_chart(runs, tmp_path / "bars.png")
    found, empty = drawn[0].axes
    assert found.get_ylim()[0] == 0
    assert found.get_ylim()[1] >= 45
    assert empty.get_ylim() == (0, 1)
    assert [text.get_text() for text in empty.texts] == ["no failures"]
    assert len(found.texts) == 0
