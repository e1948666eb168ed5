"""Whole-simulator properties: determinism across speed-ups, several boats, links and recording."""

from __future__ import annotations

import asyncio
import socket
import time

from sitl.runner import Simulation, SimulationThread
from tests.support.sitl_gcs import Gcs, mavlink, mavutil, sim_config


def unused_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def scripted_run(speedup: float, seed: int, seconds: float) -> list[dict]:
    """A run with every source of randomness on and the controller busy, and no client."""
    records: list[dict] = []
    cfg = sim_config(
        {
            "seed": seed,
            "speedup": speedup,
            "count": 2,
            "flow": {"kinds": ["uniform", "double_gyre", "gusts"], "uniform": {"drift_std_mps": 0.01}},
            "sensors": {"position": {"dropout_probability": 0.1}},
            "autopilot": {"initial_mode": "LOITER", "start_armed": True},
            "mavlink": {"endpoints": [f"udpout:127.0.0.1:{unused_udp_port()}"], "port_stride": 0},
        }
    )

    async def main() -> None:
        async with await Simulation.create(cfg, records) as sim:
            await sim.run(duration_s=seconds)

    asyncio.run(main())
    return records


def test_same_seed_same_trajectory_at_1x_and_20x():
    slow = scripted_run(1.0, seed=5, seconds=2.0)
    fast = scripted_run(20.0, seed=5, seconds=2.0)
    assert len(slow) == len(fast) == 2 * 40  # 20 Hz per boat
    assert slow == fast
    moving = [r for r in slow if abs(r["command"][0]) > 0.01]
    assert moving, "the controller should be working against the flow"
    other = scripted_run(20.0, seed=6, seconds=2.0)
    assert other != fast


def test_a_pause_of_the_process_shows_as_falling_behind_the_pace_by_pause_times_speedup():
    """A busy machine: the simulator's thread is blocked 0.1 s wall at speed-up 20, 2 s simulated; the
    missions use this to refuse runs that were not paced (mission.fly_paced)."""
    cfg = sim_config({"mavlink": {"endpoints": [f"udpout:127.0.0.1:{unused_udp_port()}"]}})
    with SimulationThread(cfg) as sim:
        time.sleep(0.3)
        sim.call(lambda s: s.reset_pace())
        time.sleep(0.3)
        assert sim.behind_max_s < 1.0  # keeping pace (a busy machine may lag a few tens of ms)
        sim.call(lambda s: time.sleep(0.1))  # the loop's thread stalls
        time.sleep(0.2)
        assert 1.8 <= sim.behind_max_s <= 4.0
        sim.call(lambda s: s.reset_pace())
        time.sleep(0.2)
        assert sim.behind_max_s < 1.0


def test_several_boats_each_on_their_own_port():
    cfg = sim_config({"count": 2, "mavlink": {"endpoints": ["tcpin:127.0.0.1:0"]}})
    with SimulationThread(cfg) as sim:
        addresses = sim.addresses()
        assert set(addresses) == {1, 2} and addresses[1] != addresses[2]
        for sysid in (1, 2):
            _, host, port = addresses[sysid][0].split(":")
            conn = mavutil.mavlink_connection(f"tcp:{host}:{port}", source_system=255, source_component=190)
            try:
                gcs = Gcs(conn, target_system=sysid)
                hb = gcs.wait_type("HEARTBEAT", 3.0)
                assert hb.get_srcSystem() == sysid
                assert gcs.set_mode(15).result == mavlink.MAV_RESULT_ACCEPTED
            finally:
                conn.close()
        modes = sim.call(lambda s: [b.autopilot.mode for b in s.boats])
        assert modes == [15, 15]


def test_boats_sharing_one_link_answer_only_for_themselves():
    cfg = sim_config({"count": 3, "mavlink": {"endpoints": ["udpin:127.0.0.1:0"], "port_stride": 0}})
    with SimulationThread(cfg) as sim:
        (address,) = {a for addrs in sim.addresses().values() for a in addrs}
        _, host, port = address.split(":")
        conn = mavutil.mavlink_connection(f"udpout:{host}:{port}", source_system=255, source_component=190)
        try:
            conn.mav.heartbeat_send(6, 8, 0, 0, 0)  # a udpin link answers those who have spoken
            gcs = Gcs(conn, target_system=2)
            gcs.wait_type("GLOBAL_POSITION_INT", sim_timeout=3.0)  # LOITER needs a position fix first
            ack = gcs.set_mode(5)
            assert ack.get_srcSystem() == 2 and ack.result == mavlink.MAV_RESULT_ACCEPTED
            seen = set()
            gcs.run_for(2.0, lambda m: None)
            for _ in range(30):
                m = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=1)
                if m is not None:
                    seen.add((m.get_srcSystem(), m.custom_mode))
            assert seen == {(1, 0), (2, 5), (3, 0)}
        finally:
            conn.close()
        positions = sim.call(lambda s: [b.state[1] for b in s.boats])
        assert positions[0] < positions[1] < positions[2]  # a row across the tank


def test_simulator_process_serves_boats_at_chosen_poses():
    from sitl.process import SimulatorProcess

    overrides = {
        "count": 2,
        "speedup": 20.0,
        "start_poses": [[1.0, 1.0, 90.0], [3.0, 2.0, 0.0]],
        "mavlink": {"endpoints": ["tcpin:127.0.0.1:0"]},
    }
    with SimulatorProcess(overrides) as sim:
        assert set(sim.addresses) == {1, 2}
        _, host, port = sim.addresses[2][0].split(":")
        conn = mavutil.mavlink_connection(f"tcp:{host}:{port}", source_system=255, source_component=190)
        try:
            gcs = Gcs(conn, target_system=2)
            pos = gcs.wait_type("LOCAL_POSITION_NED", 3.0)
            assert abs(pos.x - 3.0) < 0.02 and abs(pos.y - 2.0) < 0.02
        finally:
            conn.close()
    assert sim.returncode == 0
    assert any("stopped at t =" in line for line in sim.output)


def test_tcp_client_endpoint_connects_to_a_listening_ground_station():
    listener = mavutil.mavlink_connection("tcpin:127.0.0.1:0", source_system=255, source_component=190)
    try:
        port = listener.listen.getsockname()[1]
        cfg = sim_config({"mavlink": {"endpoints": [f"tcp:127.0.0.1:{port}"]}})
        with SimulationThread(cfg):
            gcs = Gcs(listener)
            assert gcs.wait_type("HEARTBEAT", 3.0).type == mavlink.MAV_TYPE_SURFACE_BOAT
            assert gcs.set_mode(4).result == mavlink.MAV_RESULT_ACCEPTED
    finally:
        listener.close()
