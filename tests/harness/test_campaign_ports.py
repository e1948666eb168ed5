"""A campaign run whose MAVLink port another process took first (the race between picking a free port and the
service binding it) is set up again on a new port, not counted as a failed mission. Real sockets, the real
simulator and service; only the port picker is steered onto a port that is taken."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from koopguide.harness import campaign, mission


@pytest.mark.timeout(120)
def test_a_run_whose_port_was_taken_is_flown_on_another(
    zshape_model: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    free_port = mission.free_udp_port
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))  # held by "another process" for the whole run
        port = taken.getsockname()[1]
        picks: list[int] = []

        def pick() -> int:  # the taken port first, as if another process had bound it after the pick
            picks.append(free_port() if picks else port)
            return picks[-1]

        monkeypatch.setattr(mission, "free_udp_port", pick)
        spec = campaign.RunSpec(str(zshape_model), "vectored", "calm", (-20.0, 0.0), 0, 10.0, 5.0, 0.0, 0)
        result = campaign.run_one(spec)
    assert len(picks) == 2 and picks[0] == port and picks[1] != port
    assert result.error is None and len(result.track) > 10  # it flew: the simulator's track was recorded
    assert f"port {port} is already in use by another process" in capsys.readouterr().err
