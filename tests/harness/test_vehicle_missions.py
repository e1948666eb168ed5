"""Issue 10's Done-when, per vehicle kind: the real simulator (speed-up 10, slower if it cannot keep
pace) with each boat of the family (diff_thrust, rudder, vectored) and the real service over loopback
MAVLink, a Zshape demo start, and a 0.03 m/s current toward each of the four compass sides. Ground truth
comes from the simulator's recorder. Boats unlike the simulator's default (heavier, weaker, slipping more; a
heavier rudder boat) are held to the same bounds from other demo starts.

Bounds (issue 10): arrival within 0.15 m of the goal within 75 s, then within 0.2 m for 60 s, no setpoint
above max_speed, and the state never ``arrived`` while the boat is beyond reacquire_radius_m.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import numpy as np
import pytest

from koopguide.base import data
from koopguide.guidance.settings import GuidanceConfig
from koopguide.harness import mission
from koopguide.model.learn.export import train_to_file
from tests.support import kinematic_rudder, kinematic_skid, velocity_follower

pytestmark = pytest.mark.flight  # closed-loop flights: `make test` runs them on two workers (pyproject.toml)

SPEEDUP = 10.0  # mission.fly_paced flies a run again slower if the simulator could not keep this pace
START = 1  # the Zshape demo start the CI flies (the campaign covers the others and random ones)
ARRIVE_M, ARRIVE_S = 0.15, 75.0
HOLD_M, HOLD_S = 0.2, 60.0
ESTIMATE_SLACK_M = 0.01  # the service decides on its estimate; the truth may differ by the sensor's noise
TOWARD_DEG = {"N": 0.0, "E": 90.0, "S": 180.0, "W": 270.0}


def current(direction_deg: float) -> dict:
    return {"kinds": ["uniform"], "uniform": {"speed_mps": 0.03, "direction_deg": direction_deg}}


def fly_from_demo_start(
    model: Path, start: int, toward: str, vehicle_id: str, sim_extra: dict
) -> tuple[GuidanceConfig, mission.MissionResult]:
    """A mission from Zshape demo start ``start`` in 0.03 m/s toward ``toward``, watched HOLD_S after arrival."""
    cfg, sim_cfg, _ = mission.mission_at(
        model,
        data.load_lasa("Zshape").trajectories[start][0],
        SPEEDUP,
        current(TOWARD_DEG[toward]),
        vehicle_id=vehicle_id,
        sim_extra=sim_extra,
    )
    return cfg, asyncio.run(mission.fly_paced(cfg, model, sim_cfg, ARRIVE_S, settle_s=HOLD_S))


def arrived_intervals(transitions: list[tuple[float, str]], t_end: float) -> list[tuple[float, float]]:
    """(start, end) vehicle times [s] during which the state was ``arrived``."""
    out = []
    for (t, state), nxt in zip(transitions, [*transitions[1:], (t_end, "")], strict=True):
        if state == "arrived":
            out.append((t, nxt[0]))
    return out


@pytest.mark.timeout(180)
@pytest.mark.parametrize("toward", list(TOWARD_DEG))
@pytest.mark.parametrize("vehicle", ["diff_thrust", "rudder", "vectored"])
def test_each_vehicle_arrives_and_keeps_station_in_a_current_from_each_side(
    zshape_model: Path, vehicle: str, toward: str
) -> None:
    start = data.load_lasa("Zshape").trajectories[START][0]
    cfg, sim_cfg, _ = mission.mission_at(
        zshape_model,
        start,
        SPEEDUP,
        current(TOWARD_DEG[toward]),
        vehicle_id=f"v{vehicle[0]}{toward}",
        sim_extra={"vehicle": vehicle},
    )
    result = asyncio.run(mission.fly_paced(cfg, zshape_model, sim_cfg, ARRIVE_S, settle_s=HOLD_S))
    assert_arrives_and_holds(cfg, result, f"{vehicle}, current toward {toward}")


# An independent boat: twice the mass and yaw inertia, 20% less thrust ahead and 45% less astern, a hull that
# slips sideways more easily (Y_v -3 instead of -5 kg/s); the guidance is not told any of it.
HEAVY = {
    "vehicle": "diff_thrust",
    "vessel": {
        "hull": {"mass_kg": 2.0, "yaw_inertia_kgm2": 0.02, "linear_damping_sway_kgps": -3.0},
        "thrusters": {"max_forward_thrust_n": 0.12, "max_reverse_thrust_n": 0.05},
    },
}


@pytest.mark.timeout(180)
@pytest.mark.parametrize(("start", "toward"), [(0, "S"), (6, "W")])
def test_a_heavier_weaker_skid_steer_boat_arrives_and_keeps_station_too(
    zshape_model: Path, start: int, toward: str
) -> None:
    cfg, result = fly_from_demo_start(zshape_model, start, toward, f"heavy{toward}", HEAVY)
    assert_arrives_and_holds(cfg, result, f"heavy diff_thrust from start {start}, current toward {toward}")


@pytest.mark.timeout(180)
def test_a_heavier_skid_steer_boat_drifts_onto_a_goal_downstream_instead_of_pivoting_short_of_it(
    zshape_model: Path,
) -> None:
    """Zshape start 4 in a current toward S comes down onto the goal bow downstream. Turned after the water velocity
    that remains when the ground velocity wanted is nearly the current's, this boat pivoted 0.3 m short of the goal for
    35 s and arrived after 71.7 s; on the current's line, stern to it, it drifts in (44.5-47.5 s, law/maneuver.py).
    Begun only under 0.3 of the current's speed, 3 of 23 flights beside two busy processes came down 16 deg off
    straight downstream just over it and arrived after 71.4 s (stop 43's CI); under 0.5, 14 of 14 in 43.8-49.6 s."""
    cfg, result = fly_from_demo_start(zshape_model, 4, "S", "heavydrift", HEAVY)
    assert_arrives_and_holds(cfg, result, "heavy diff_thrust from start 4, current toward S")
    assert result.arrival_time_s <= 60.0, result.arrival_time_s


# A heavier rudder boat: twice the mass and yaw inertia, 20% less thrust ahead and 45% less astern. Told to stop
# it runs on about 3 s times its speed (the simulator's, 1.7 s): on ramps made for the simulator's boats it ran
# 0.2 m past the goal and held 0.18-0.23 m toward N (5 of 7 demo starts over the bound); ramps from its stopping
# time learned in the turn probe (estimation/speed_lag.py), 0.10-0.16 m.
HEAVY_RUDDER = {
    "vehicle": "rudder",
    "vessel": {
        "hull": {"mass_kg": 2.0, "yaw_inertia_kgm2": 0.02},
        "thrusters": {"max_forward_thrust_n": 0.12, "max_reverse_thrust_n": 0.05},
    },
}


@pytest.mark.timeout(180)
def test_a_heavier_rudder_boat_does_not_run_past_the_goal(zshape_model: Path) -> None:
    start, toward = 6, "N"
    cfg, sim_cfg, _ = mission.mission_at(
        zshape_model,
        data.load_lasa("Zshape").trajectories[start][0],
        SPEEDUP,
        current(TOWARD_DEG[toward]),
        vehicle_id="heavyrudder",
        sim_extra=HEAVY_RUDDER,
    )
    result = asyncio.run(mission.fly_paced(cfg, zshape_model, sim_cfg, ARRIVE_S, settle_s=HOLD_S))
    assert_arrives_and_holds(cfg, result, f"heavy rudder boat from start {start}, current toward {toward}")


@pytest.mark.timeout(180)
@pytest.mark.parametrize(("heading", "toward"), [("fixed", "N"), ("fixed", "W"), ("asked", "E"), ("course", "W")])
def test_a_vehicle_whose_velocity_through_the_water_follows_the_setpoint_arrives_and_keeps_station(
    zshape_model: Path, monkeypatch: pytest.MonkeyPatch, heading: str, toward: str
) -> None:
    """Issue 10's first vehicle, independent of the simulator's hulls (tests/support/velocity_follower.py): it goes
    where it is sent, holonomically. One whose heading stays where it started was taken for a rudder boat (it did
    not turn when asked), steered by that heading onto lines it never turned to, and arrived in 0 of 12 missions
    (Zshape starts 0, 3 and 6 x 4 currents); the turn probe now sees it go across its heading, and it is sent
    velocities, its current measured as its ground velocity less the velocity sent. So is one whose heading is the
    direction it moves in (held as a rudder boat, it flipped end for end when sent astern, 10 of 12). One that turns
    to the heading asked is a boat that turns in place."""
    velocity_follower.install(monkeypatch, heading=heading)
    cfg, result = fly_from_demo_start(zshape_model, 3, toward, f"follow{heading[0]}{toward}", {"vehicle": "vectored"})
    assert_arrives_and_holds(cfg, result, f"velocity follower (heading {heading}), current toward {toward}")


@pytest.mark.timeout(180)
@pytest.mark.parametrize(("start", "toward", "stops_at_zero"), [(2, "E", False), (5, "S", True)])
def test_a_kinematic_skid_steer_boat_that_pivots_on_guided_targets_arrives_and_keeps_station(
    zshape_model: Path, monkeypatch: pytest.MonkeyPatch, start: int, toward: str, stops_at_zero: bool
) -> None:
    """Issue 10's second vehicle, independent of the simulator's hulls (tests/support/kinematic_skid.py): heading
    plus speed over ground, and pivot turns beyond 60 deg on guided targets too (the simulator's boat, as Rover's
    source, pivots only in waypoint navigation), with or without Rover's stop controller. From the 7 Zshape demo
    starts x 4 currents: 28 of 28 either way (stop 57)."""
    kinematic_skid.install(monkeypatch, stops_at_zero=stops_at_zero)
    cfg, result = fly_from_demo_start(zshape_model, start, toward, f"kskid{toward}", {"vehicle": "diff_thrust"})
    assert_arrives_and_holds(cfg, result, f"kinematic skid steer (stop controller {stops_at_zero}), toward {toward}")


@pytest.mark.timeout(180)
@pytest.mark.parametrize(("toward", "radius_m", "tau_s"), [("N", 0.6, 1.0), ("S", 0.6, 1.0), ("W", 1.2, 2.0)])
def test_a_kinematic_rudder_boat_that_holds_its_ground_at_speed_0_arrives_and_keeps_station(
    zshape_model: Path, monkeypatch: pytest.MonkeyPatch, toward: str, radius_m: float, tau_s: float
) -> None:
    """Issue 10's third vehicle, independent of the simulator's hulls (tests/support/kinematic_rudder.py): no turn
    without way, and an autopilot without Rover's stop controller, so speed 0 holds its ground in a current instead
    of letting it drift. Holds that began 0.15-0.3 m upstream of the goal sat there for good, sent 0 to drift onto
    it (0.6 m circle, 1 s lag: from the 7 Zshape demo starts, toward N 1 of 7 and toward S 2 of 7 arrived); the hold
    now sees the boat is not carried and backs it down (28 of 28 over the four currents). With a 1.2 m circle and a
    2 s lag it also took on its hold crossing the goal at way and ran on 0.22-0.31 m after arriving (12 of 28; toward
    N and W none); it now arrives only once it would come to rest within the radius (28 of 28)."""
    kinematic_rudder.install(monkeypatch, radius_m=radius_m, tau_s=tau_s)
    cfg, result = fly_from_demo_start(zshape_model, 3, toward, f"kinrud{toward}", {"vehicle": "rudder"})
    assert_arrives_and_holds(cfg, result, f"kinematic rudder ({radius_m} m circle, {tau_s} s lag), toward {toward}")


@pytest.fixture(scope="module")
def zshape_model_seed_3(tmp_path_factory: pytest.TempPathFactory, zshape: data.Demonstrations) -> Path:
    """Zshape trained with the shipped defaults, seed 3: another field than the one the guidance was tuned on."""
    path = tmp_path_factory.mktemp("models") / "zshape-seed3.pt"
    train_to_file(zshape, path, seed=3)
    return path


@pytest.mark.timeout(180)
def test_a_kinematic_rudder_boat_that_holds_its_ground_is_not_taken_for_one_that_pivots(
    zshape_model_seed_3: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Start 3 in a current toward E heads east, with the current: asked speed 0 in the turn probe, this boat holds
    its ground with sternway through the water, and turns on it (10 deg in 4 s on its 0.6 m circle). Read as a turn in
    place, it was guided as a boat that pivots onto the tank's east wall, then held bow downstream upstream of the
    goal at speed 0, waiting on a drift that never came: on this model 4 of the 7 starts toward E missed (stop 58)."""
    kinematic_rudder.install(monkeypatch)
    cfg, result = fly_from_demo_start(zshape_model_seed_3, 3, "E", "kinrud3E", {"vehicle": "rudder"})
    assert_arrives_and_holds(cfg, result, "kinematic rudder (0.6 m circle), model seed 3, start 3 toward E")


@pytest.mark.timeout(180)
@pytest.mark.parametrize("toward", ["N", "E"])
def test_a_kinematic_rudder_boat_that_does_not_go_astern_arrives_and_keeps_station(
    zshape_model: Path, monkeypatch: pytest.MonkeyPatch, toward: str
) -> None:
    """A rudder boat whose motor does not reverse (tests/support/kinematic_rudder.py, ``astern_mps`` 0, Rover's stop
    controller): asked astern, it lies in the water. Its planned approach asked 0.28 m/s astern for 50 s while the
    current carried it 1 m off (from the 7 Zshape demo starts, 12 of 28 over the four currents; toward N none,
    closest 1.1 m). The helm now sees it gather no sternway and guides it ahead only (estimation/speed_lag.py
    ``SternwayTrial``; law/line_approach.py): 27 of 28."""
    kinematic_rudder.install(monkeypatch, astern_mps=0.0, stops_at_zero=True)
    cfg, result = fly_from_demo_start(zshape_model, 0, toward, f"ahead{toward}", {"vehicle": "rudder"})
    assert_arrives_and_holds(cfg, result, f"kinematic rudder without astern, toward {toward}")


@pytest.mark.timeout(180)
@pytest.mark.parametrize("start", [5, 1])
def test_a_kinematic_rudder_boat_without_astern_that_holds_its_ground_at_speed_0_arrives_and_keeps_station(
    zshape_model: Path, monkeypatch: pytest.MonkeyPatch, start: int
) -> None:
    """A rudder boat whose motor does not reverse and whose autopilot holds its ground at speed 0
    (tests/support/kinematic_rudder.py, ``astern_mps`` 0, no stop controller), current toward N: the capture search's
    model drifted it at speed 0 and sent 0 for 20 s while the boat held its ground and crept across the goal 47 deg
    off its line (toward N 3 of 7 met the bounds: start 5 never arrived, start 1 held within 0.203 m). Now speed 0 is
    seen to hold its ground and modelled so (estimation/speed_lag.py ``RestHold``, law/capture.py): toward N 20 of
    21 over three flights (holds within 0.13-0.21 m; start 5 within 0.173-0.185 m, start 1 within 0.132-0.160 m)."""
    kinematic_rudder.install(monkeypatch, astern_mps=0.0)
    cfg, result = fly_from_demo_start(zshape_model, start, "N", f"rest{start}N", {"vehicle": "rudder"})
    assert_arrives_and_holds(cfg, result, f"kinematic rudder without astern or stop controller, start {start}, N")


def assert_arrives_and_holds(cfg: GuidanceConfig, result: mission.MissionResult, label: str) -> None:
    """Issue 10's bounds on the simulator's ground truth (see the module docstring)."""
    track = result.track
    distance = np.hypot(track[:, 1], track[:, 2])
    assert result.arrived, f"{label}: closest {distance.min():.3f} m, final {distance[-1]:.3f} m"
    assert result.arrival_time_s <= ARRIVE_S, result.arrival_time_s
    assert distance.min() <= ARRIVE_M + ESTIMATE_SLACK_M  # the true boat, not only the estimate
    assert result.max_setpoint_mps <= cfg.command.max_speed_mps, result.max_setpoint_mps  # not even by an ulp
    after = track[:, 0] >= result.arrived_at_s
    assert track[after, 0][-1] - result.arrived_at_s >= HOLD_S - 1.0  # the hold was watched for the whole 60 s
    assert distance[after].max() <= HOLD_M, f"hold error {distance[after].max():.3f} m"
    # honest states: never 'arrived' while the true boat is beyond reacquire_radius_m (plus the estimate's noise)
    for t0, t1 in arrived_intervals(result.transitions, float(track[-1, 0])):
        inside = (track[:, 0] >= t0 + 0.2) & (track[:, 0] <= t1)
        if inside.any():
            far = distance[inside].max()
            assert far <= cfg.arrival.reacquire_radius_m + ESTIMATE_SLACK_M, f"arrived at {far:.3f} m ({t0:.1f} s)"


@pytest.mark.timeout(180)
@pytest.mark.parametrize("toward", [None, "E"])
def test_a_skid_steer_boat_starting_close_to_the_goal_and_facing_away_backs_onto_it(
    zshape_model: Path, toward: str | None
) -> None:
    """The start that made the skid-steer boat orbit the goal (0.37 m away, facing away; docs/missions.md): at
    the speed floor its turning circle was wider than its distance to the goal."""
    start_ned = np.array([-0.31, -0.21])
    away_deg = float(np.degrees(np.arctan2(start_ned[1], start_ned[0])))
    flow = None if toward is None else current(TOWARD_DEG[toward])
    cfg, sim_cfg, _ = mission.mission_at(
        zshape_model,
        data.load_lasa("Zshape").trajectories[START][0],
        SPEEDUP,
        flow,
        vehicle_id=f"near{toward}",
        sim_extra={"vehicle": "diff_thrust", "start_poses": [[*start_ned.tolist(), away_deg]]},
    )
    result = asyncio.run(mission.fly_paced(cfg, zshape_model, sim_cfg, ARRIVE_S, settle_s=HOLD_S))
    distance = np.hypot(result.track[:, 1], result.track[:, 2])
    assert distance[0] == pytest.approx(0.375, abs=0.01)  # it did start there
    assert result.arrived and result.arrival_time_s <= 30.0, result.arrival_time_s  # no orbit: ~10 s
    after = result.track[:, 0] >= result.arrived_at_s
    assert distance[after].max() <= HOLD_M, f"hold error {distance[after].max():.3f} m"
    assert result.max_setpoint_mps <= cfg.command.max_speed_mps


@pytest.mark.timeout(180)
@pytest.mark.parametrize(("pose", "toward"), [((-0.16, 0.10, -99.6), "N"), ((0.04, -0.05, 109.4), "S")])
def test_a_skid_steer_boat_starting_at_the_goal_across_the_current_keeps_station(
    zshape_model: Path, pose: tuple[float, float, float], toward: str
) -> None:
    """By the goal from the start, its hull across the current: turning at 7 deg/s to face it upstream, the boat
    was carried 0.24-0.38 m off while the status said arrived (hold p95 0.37 m in a default campaign, --seed 4). It
    turns to the nearer end of the current's line, and has arrived only once its hull lies along it."""
    extra = {"vehicle": "diff_thrust", "start_poses": [list(pose)]}  # the demo start's point is not flown from
    cfg, result = fly_from_demo_start(zshape_model, START, toward, f"across{toward}", extra)
    assert np.hypot(*result.track[0, 1:3]) <= cfg.arrival.radius_m + 0.05  # it did start by the goal
    assert_arrives_and_holds(cfg, result, f"diff_thrust by the goal at {pose}, current toward {toward}")
