"""The report's figures drawn from data a user's own settings shape."""

import numpy as np
import pandas as pd
import pytest
from matplotlib.image import imread

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
