"""The operator's hold in the supervisor, without sockets: OperatorHold events against the point-mass boat
of test_supervisor. Conventions: local NED [m], [m/s]; headings [rad] from north; vehicle seconds."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from koopguide.guidance.events import Arm, OperatorHold, SetMode
from koopguide.guidance.law.command import GuidanceState
from koopguide.mavlink.rover import GUIDED
from tests.guidance.test_supervisor import MANUAL, Bench

S = GuidanceState


def hold(bench: Bench, active: bool, source: str = "dashboard@lab") -> None:
    bench.sup.handle(OperatorHold(bench.wall, active, source))


def test_a_hold_sends_zero_at_the_current_heading_until_resumed_and_the_boat_stays(zshape_model: Path) -> None:
    bench = Bench(zshape_model)
    moving = bench.fly(3.0)
    assert moving[-1].state is S.GUIDING and math.hypot(*moving[-1].velocity_ned) > 0.05
    heading = bench.heading  # the boat's heading now (the next ATTITUDE reports it)
    hold(bench, True)
    where = bench.p.copy()
    stall_s = bench.cfg.failsafe.stall_s
    held = bench.fly(stall_s + 5.0)  # longer than the progress watchdog's window
    assert all(d.state is S.HOLD and d.reason == "operator hold (dashboard@lab)" for d in held)
    assert all(d.velocity_ned == (0.0, 0.0) and d.yaw_rad == pytest.approx(heading) for d in held)
    assert float(np.hypot(*(bench.p - where))) < 1e-9  # zero velocity obeyed: the boat did not move
    assert [s for _, s in bench.sup.transitions][-2:] == ["guiding", "hold"]
    notes = [n.text for n in bench.sup.take_notes()]
    assert "operator hold from dashboard@lab" in notes
    hold(bench, False, "dashboard@ops")
    resumed = bench.fly(3.0)
    # guiding again at once; the held time is not taken for a stall (no direct pursuit)
    assert all(d.state is S.GUIDING and not d.degraded for d in resumed)
    assert math.hypot(*resumed[-1].velocity_ned) > 0.05
    assert float(np.hypot(*(bench.p - where))) > 0.15
    assert any("operator resume from dashboard@ops" in n.text for n in bench.sup.take_notes())


def test_a_held_vehicle_is_neither_switched_to_guided_nor_armed_nor_sent_setpoints(zshape_model: Path) -> None:
    bench = Bench(zshape_model)
    hold(bench, True, "ops")
    bench.heartbeat(MANUAL, armed=False)
    for _ in range(40):  # 2 s, longer than command_retry_s
        bench.fix()
        d = bench.tick()
        assert d.state is S.HOLD and d.reason == "operator hold (ops)"
        assert d.velocity_ned is None  # not in GUIDED: nothing to send
        assert not any(isinstance(r, SetMode | Arm) for r in d.requests)
        bench.advance()
    hold(bench, False, "ops")
    bench.fix()
    d = bench.tick()
    assert d.state is S.WAITING and SetMode(GUIDED) in d.requests  # resumed: takes the vehicle again


def test_a_hold_wins_over_a_stale_position_and_without_a_heartbeat_the_link_comes_first(zshape_model: Path) -> None:
    bench = Bench(zshape_model)
    bench.fly(1.0)
    hold(bench, True)
    bench.advance(1.0)  # positions stale too
    bench.heartbeat()
    d = bench.tick()
    assert d.state is S.HOLD and d.reason == "operator hold (dashboard@lab)" and d.velocity_ned == (0.0, 0.0)
    bench.advance(bench.cfg.mavlink.link_timeout_s + 1.0)  # no heartbeat: nothing can be sent anyway
    d = bench.tick()
    assert d.state is S.WAITING and d.reason == "no vehicle heartbeat" and d.velocity_ned is None


def test_a_resume_without_a_hold_changes_nothing(zshape_model: Path) -> None:
    bench = Bench(zshape_model)
    bench.fly(1.0)
    bench.sup.take_notes()
    hold(bench, False)
    assert bench.sup.operator_hold is None and bench.sup.take_notes() == []
    assert bench.fly(0.5)[-1].state is S.GUIDING
