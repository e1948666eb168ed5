"""The distance to the goal along the field (law/field_distance.py) and the progress watchdog that uses it
(estimation/progress.py), on the real trained Zshape field: NED [m], the README's frame (0.04 m per unit).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from koopguide.guidance import settings
from koopguide.guidance.estimation.progress import ProgressWatchdog
from koopguide.guidance.law.command import GuidanceLaw
from koopguide.model.field import load_field


def zshape_law(model: Path) -> GuidanceLaw:
    cfg = settings.load(overrides={"frame": {"goal_ned": [0.0, 0.0], "scale": 0.04, "heading_deg": 90.0}})
    return GuidanceLaw.from_config(load_field(model), cfg)


def test_the_distance_along_the_field_shrinks_along_a_streamline_and_is_never_shorter_than_straight(
    zshape_model: Path,
) -> None:
    law = zshape_law(zshape_model)
    rng = np.random.default_rng(3)
    lo, hi = law.frame.to_ned(law.domain_lo), law.frame.to_ned(law.domain_hi)
    box_lo, box_hi = np.minimum(lo, hi), np.maximum(lo, hi)
    for p in rng.uniform(box_lo, box_hi, size=(40, 2)):
        along = law.distance_along_field(p)
        assert along >= law.distance_to_goal(p) - 0.02  # interpolation error of a 48 x 48 table, at most 2 cm
    # follow the streamline from the first demonstration's start: the distance along it falls by what is travelled
    p = law.frame.to_ned(law.field.goal + np.array([-39.6, 38.9]) - law.field.goal)
    start = law.distance_along_field(p)
    travelled, samples = 0.0, [start]
    for _ in range(400):
        v = law.field_velocity_ned(p)
        step = v / np.hypot(*v) * 0.01  # 1 cm along the field
        p = p + step
        travelled += 0.01
        samples.append(law.distance_along_field(p))
        if law.distance_to_goal(p) < 0.3:
            break
    assert start > 4.0  # the Z is far longer than the 2.3 m straight line
    assert samples[-1] < start - 0.8 * travelled  # it falls about as fast as the boat travels
    assert np.all(np.diff(samples[::20]) < 0)  # and keeps falling


def test_a_boat_shuttling_across_a_hairpin_of_the_field_is_stalled(zshape_model: Path) -> None:
    law = zshape_law(zshape_model)
    corner = law.frame.to_ned(np.array([0.0, 40.0]) + law.field.goal - law.field.goal)  # the Z's top corner
    watchdog = ProgressWatchdog(stall_s=15.0, stall_progress_m=0.05)
    odometer_only = ProgressWatchdog(stall_s=15.0, stall_progress_m=0.05)
    stalled = stalled_odometer = False
    for k in range(int(30 / 0.1)):  # 0.3 m back and forth every 4 s, 30 s
        t = 0.1 * k
        offset = 0.15 * np.sin(2 * np.pi * t / 4.0)
        p = corner + np.array([0.0, offset])
        velocity = np.array([0.0, np.cos(2 * np.pi * t / 4.0)])  # the way it moves is the way it is told
        distance = law.distance_to_goal(p)
        stalled |= watchdog.update(t, p, velocity, distance, law.distance_along_field(p))
        stalled_odometer |= odometer_only.update(t, p, velocity, distance)
    assert stalled  # no progress along the field in 15 s
    assert not stalled_odometer  # the distance made good along a turning wanted direction would be fooled
