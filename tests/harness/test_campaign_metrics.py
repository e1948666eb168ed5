"""The campaign's path metrics (koopguide/harness/campaign.py): streamlines and distances to them, pure math."""

from __future__ import annotations

import numpy as np

from koopguide.harness.campaign import distance_to_polyline, streamline


def toward_origin(p: np.ndarray) -> np.ndarray:
    return -np.asarray(p, dtype=float)


def test_a_streamline_runs_from_the_start_to_the_goals_radius_and_paths_are_measured_from_it() -> None:
    line = streamline(toward_origin, np.array([1.0, 0.0]), np.zeros(2), 0.15)
    assert line is not None
    assert np.allclose(line[0], [1.0, 0.0]) and 0.14 <= float(np.hypot(*line[-1])) <= 0.15
    assert np.allclose(line[:, 1], 0.0)  # straight in
    points = np.array([[0.5, 0.2], [0.5, -0.3], [1.0, 0.0], [2.0, 0.0]])
    assert np.allclose(distance_to_polyline(points, line), [0.2, 0.3, 0.0, 1.0], atol=1e-9)


def test_a_start_within_the_arrival_radius_has_a_one_point_streamline_and_its_distances_are_to_that_point() -> None:
    # a drawn start can fall within the arrival radius (seed 8, start 10 of the campaign): the metric must not fail
    start = np.array([0.05, 0.05])
    line = streamline(toward_origin, start, np.zeros(2), 0.15)
    assert line is not None and line.shape == (1, 2)
    points = np.array([[0.05, 0.05], [0.05, 0.35], [-0.25, 0.05]])
    assert np.allclose(distance_to_polyline(points, line), [0.0, 0.3, 0.3])
