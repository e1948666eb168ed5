"""``koopguide bench missions``: a closed-loop campaign of simulated missions, vehicles x flows x starts.

Every run is a whole mission (:func:`koopguide.harness.mission.fly`): the bundled simulator with one boat
of a given kind, the real guidance service over loopback MAVLink, sensor noise and latency, at speed-up,
in worker processes. Starts are drawn uniformly from the demonstrations' box enlarged by 10% per side
(not only the demonstrations' own starts). Per run and aggregated per vehicle and flow it measures the
arrival rate, the time to arrive and its ratio to the ideal time (the field's streamline from the start,
driven at ``max_speed``), the path's deviation from that streamline (RMS and max), the hold error p95
over the ``hold_s`` seconds after arrival, and the largest setpoint. Output: ``report.md``,
``paths.png`` and ``runs.json`` (:mod:`koopguide.harness.campaign_report`).

Conventions: local NED metres, simulated seconds, m/s.
"""

from __future__ import annotations

import argparse
import asyncio
import concurrent.futures
import itertools
import json
import multiprocessing
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from koopguide.base.flags import name_list

VEHICLES: tuple[str, ...] = ("diff_thrust", "rudder", "vectored")
CURRENT_MPS = 0.03
PORT_ATTEMPTS = 3  # a run whose MAVLink port another process took first is set up again on a new one


def _uniform(direction_deg: float) -> dict[str, Any]:
    return {"kinds": ["uniform"], "uniform": {"speed_mps": CURRENT_MPS, "direction_deg": direction_deg}}


#: The flows of the campaign, as the simulator's ``flow`` section (a current "toward" a compass side).
FLOWS: dict[str, dict[str, Any]] = {
    "calm": {"kinds": ["none"]},
    "toward_N": _uniform(0.0),
    "toward_E": _uniform(90.0),
    "toward_S": _uniform(180.0),
    "toward_W": _uniform(270.0),
    # The Zshape domain of the README's mission spans N -0.1 .. 2.0 m, E -1.8 .. 0 m.
    # A Lamb-Oseen vortex centred on it: about 0.05 m/s at its core radius.
    "vortex": {
        "kinds": ["vortex"],
        "vortex": {"center_ned_m": [0.9, -0.9], "circulation_m2ps": 0.2, "core_radius_m": 0.4},
    },
    # A double gyre over it (2s x s = 2.5 m x 1.25 m, north x east): up to ~0.09 m/s, period 10 s.
    "double_gyre": {
        "kinds": ["double_gyre"],
        "double_gyre": {"origin_ned_m": [-0.3, -1.5], "scale_m": 1.25, "amplitude_mps": 0.02},
    },
}
#: Sensor noise and latency of every run (the simulator's position sensor).
SENSORS = {"sensors": {"position": {"noise_std_m": 0.005, "velocity_noise_std_mps": 0.01, "latency_s": 0.05}}}


@dataclass(frozen=True)
class RunSpec:
    model: str  # model file
    vehicle: str  # the simulator's vehicle kind
    flow: str  # a key of FLOWS
    start_model: tuple[float, float]  # start point [model units]
    start_index: int
    speedup: float
    timeout_s: float  # simulated seconds allowed to arrive
    hold_s: float  # simulated seconds watched after arrival
    seed: int


@dataclass
class RunResult:
    vehicle: str
    flow: str
    start_index: int
    start_ned: tuple[float, float]
    arrived: bool
    time_to_arrive_s: float | None
    ideal_time_s: float | None  # along the streamline from the start, at max speed
    time_ratio: float | None
    deviation_rms_m: float | None  # of the path before arrival from the streamline through the start
    deviation_max_m: float | None
    hold_p95_m: float | None  # distance to the goal over hold_s after arrival, 95th percentile
    hold_max_m: float | None
    final_distance_m: float
    max_setpoint_mps: float
    arrived_but_far: bool  # the service said arrived while the true boat was beyond the reacquire radius
    track: list[list[float]]  # (T, 3) t, N, E, decimated for the plots
    speedup: float = 0.0  # as flown: lower than asked when the simulator could not keep that pace (fly_paced)
    error: str | None = None


def streamline(
    velocity_ned: Any,
    start: np.ndarray,
    goal: np.ndarray,
    radius_m: float,
    step_m: float = 0.01,
    max_steps: int = 20_000,
) -> np.ndarray | None:
    """The field's streamline from ``start`` (NED, m) until within ``radius_m`` of ``goal``: (K, 2) points,
    or None when it does not get there in ``max_steps`` steps of ``step_m`` (a stall or a cycle)."""
    points = [np.asarray(start, dtype=float)]
    p = points[0]
    for _ in range(max_steps):
        if np.hypot(*(p - goal)) <= radius_m:
            return np.array(points)
        v = np.asarray(velocity_ned(p), dtype=float)
        speed = float(np.hypot(*v))
        if not np.isfinite(speed) or speed < 1e-9:
            return None
        p = p + step_m * v / speed  # arc-length steps (Euler along the unit tangent)
        points.append(p)
    return None


def distance_to_polyline(points: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Distance of each of ``points`` (T, 2) to the polyline ``line`` (K, 2) [m]; a one-point line (a start already
    within the arrival radius: its streamline ends where it begins) is that point."""
    if len(line) == 1:
        return np.hypot(*(points - line[0]).T)
    a, b = line[:-1], line[1:]
    ab = b - a
    length2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-18)
    out = np.empty(len(points))
    for i in range(0, len(points), 256):  # chunks: (256, K) at a time
        p = points[i : i + 256, None, :]
        s = np.clip(np.einsum("tkj,kj->tk", p - a, ab) / length2, 0.0, 1.0)
        nearest = a + s[..., None] * ab
        out[i : i + 256] = np.min(np.linalg.norm(p - nearest, axis=-1), axis=1)
    return out


def draw_starts(bounds_lo: np.ndarray, bounds_hi: np.ndarray, n: int, seed: int) -> np.ndarray:
    """``n`` starts uniform in the box grown by 10% per side (model units)."""
    pad = 0.1 * (bounds_hi - bounds_lo)
    return np.random.default_rng(seed).uniform(bounds_lo - pad, bounds_hi + pad, size=(n, len(bounds_lo)))


def run_one(spec: RunSpec) -> RunResult:
    """One mission in this process (a worker), measured against the ground truth."""
    import logging

    from koopguide.harness.mission import fly_paced, mission_at
    from koopguide.mavlink.endpoint import PortInUseError

    logging.basicConfig(level=logging.ERROR)  # the service's state changes are in the results, not on stderr

    sim_extra = {**SENSORS, "vehicle": spec.vehicle}
    for attempt in range(1, PORT_ATTEMPTS + 1):
        cfg, sim_cfg, pose = mission_at(
            Path(spec.model),
            np.array(spec.start_model),
            spec.speedup,
            FLOWS[spec.flow],
            vehicle_id=f"c{spec.start_index}",
            seed=spec.seed,
            sim_extra=sim_extra,
        )
        try:
            result = asyncio.run(fly_paced(cfg, Path(spec.model), sim_cfg, spec.timeout_s, settle_s=spec.hold_s))
            break
        except PortInUseError as exc:
            # the free port mission_at picked was bound by another process (a parallel worker) before the service
            # could bind it: nothing was flown, so pick another
            if attempt == PORT_ATTEMPTS:
                raise
            print(f"mission: {exc}; flying it on another port", file=sys.stderr)
    law, goal = result.law, result.law.goal_ned
    track = result.track
    line = streamline(law.field_velocity_ned, np.array(pose[:2]), goal, cfg.arrival.radius_m)
    ideal = None if line is None else float(np.sum(np.hypot(*np.diff(line, axis=0).T))) / cfg.command.max_speed_mps
    dev_rms = dev_max = hold_p95 = hold_max = None
    t_arr = result.arrived_at_s
    before = track[track[:, 0] <= t_arr] if t_arr is not None else track
    if line is not None and len(before) > 1:
        dev = distance_to_polyline(before[:, 1:], line)
        dev_rms, dev_max = float(np.sqrt(np.mean(dev**2))), float(dev.max())
    if t_arr is not None:
        after = track[(track[:, 0] >= t_arr) & (track[:, 0] <= t_arr + spec.hold_s)]
        if len(after):
            d = np.hypot(after[:, 1] - goal[0], after[:, 2] - goal[1])
            hold_p95, hold_max = float(np.percentile(d, 95)), float(d.max())
    reacquire = getattr(cfg.arrival, "reacquire_radius_m", None)
    far = bool(hold_max is not None and reacquire is not None and _arrived_while_far(result, track, goal, reacquire))
    arrive = result.arrival_time_s
    return RunResult(
        vehicle=spec.vehicle,
        flow=spec.flow,
        start_index=spec.start_index,
        start_ned=(pose[0], pose[1]),
        arrived=result.arrived,
        time_to_arrive_s=arrive,
        ideal_time_s=ideal,
        time_ratio=None if arrive is None or not ideal else arrive / ideal,
        deviation_rms_m=dev_rms,
        deviation_max_m=dev_max,
        hold_p95_m=hold_p95,
        hold_max_m=hold_max,
        final_distance_m=result.final_distance_m,
        max_setpoint_mps=result.max_setpoint_mps,
        arrived_but_far=far,
        track=np.round(track[:: max(1, len(track) // 400)], 3).tolist(),
        speedup=result.sim_speedup,
    )


def _arrived_while_far(result: Any, track: np.ndarray, goal: np.ndarray, reacquire_m: float) -> bool:
    """Whether some stretch the service reported as ``arrived`` had the true boat beyond ``reacquire_m``."""
    transitions = [*result.transitions, (np.inf, "end")]
    for (t0, state), (t1, _) in itertools.pairwise(transitions):
        if state != "arrived":
            continue
        inside = track[(track[:, 0] >= t0 + 1.0) & (track[:, 0] < t1)]  # 1 s: the estimate's lag
        if len(inside) and np.hypot(inside[:, 1] - goal[0], inside[:, 2] - goal[1]).max() > reacquire_m:
            return True
    return False


def _run_guarded(spec: RunSpec) -> RunResult:
    try:
        return run_one(spec)
    except Exception as exc:
        return RunResult(
            spec.vehicle,
            spec.flow,
            spec.start_index,
            (float("nan"), float("nan")),
            False,
            None,
            None,
            None,
            None,
            None,
            None,
            None,
            float("nan"),
            0.0,
            False,
            [],
            error=f"{type(exc).__name__}: {exc}",
        )


def run_campaign(specs: list[RunSpec], workers: int, progress: bool = True) -> list[RunResult]:
    """All runs, ``workers`` processes at a time (spawned: no state shared with this process)."""
    results: list[RunResult] = []
    started = time.monotonic()
    context = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        for result in pool.map(_run_guarded, specs):
            results.append(result)
            if progress:
                verdict = (
                    ("ERROR " + result.error)
                    if result.error
                    else (
                        f"arrived in {result.time_to_arrive_s:.1f} s"
                        if result.arrived
                        else f"did not arrive ({result.final_distance_m:.2f} m)"
                    )
                )
                print(
                    f"  [{len(results):3d}/{len(specs)}] {result.vehicle:11s} {result.flow:11s} "
                    f"start {result.start_index:2d}: {verdict}  ({time.monotonic() - started:.0f} s)",
                    file=sys.stderr,
                    flush=True,
                )
    return results


def main(argv: list[str] | None = None) -> int:
    from koopguide.harness import campaign_report

    parser = argparse.ArgumentParser(prog="koopguide bench missions", description=__doc__.split("\n")[0])
    parser.add_argument("--model", type=Path, help="model file (default: train Zshape into OUT/zshape.pt once)")
    parser.add_argument("--vehicles", type=name_list, default=list(VEHICLES), help=f"of {', '.join(VEHICLES)}")
    parser.add_argument("--flows", type=name_list, default=list(FLOWS), help=f"of {', '.join(FLOWS)}")
    parser.add_argument("--starts", type=int, default=6, help="random starts per vehicle and flow")
    parser.add_argument("--workers", type=int, default=2, help="parallel worker processes")
    parser.add_argument(
        "--speedup",
        type=float,
        default=10.0,
        help="simulated seconds per wall second (x20 starves the service on a loaded machine)",
    )
    parser.add_argument("--timeout-s", type=float, default=120.0, help="simulated seconds allowed to arrive")
    parser.add_argument("--hold-s", type=float, default=60.0, help="simulated seconds watched after arrival")
    parser.add_argument("--seed", type=int, default=0, help="seed of the starts and of the simulator")
    parser.add_argument("-o", "--output", type=Path, required=True, help="folder for report.md, paths.png, runs.json")
    args = parser.parse_args(argv)
    unknown = [v for v in args.vehicles if v not in VEHICLES] + [f for f in args.flows if f not in FLOWS]
    if unknown:
        raise ValueError(
            f"unknown vehicle or flow {unknown[0]!r} (vehicles: {', '.join(VEHICLES)}; flows: {', '.join(FLOWS)})"
        )
    for name, value, lo in (("--starts", args.starts, 1), ("--workers", args.workers, 1)):
        if value < lo:
            raise ValueError(f"{name} must be >= {lo}, got {value}")
    if not (args.speedup > 0 and args.timeout_s > 0 and args.hold_s > 0):
        raise ValueError("--speedup, --timeout-s and --hold-s must be > 0")
    args.output.mkdir(parents=True, exist_ok=True)
    model = args.model or _default_model(args.output)
    from koopguide.model.field import load_field

    field_ = load_field(model)
    starts = draw_starts(*field_.bounds, args.starts, args.seed)
    specs = [
        RunSpec(
            str(model), v, f, (float(s[0]), float(s[1])), i, args.speedup, args.timeout_s, args.hold_s, args.seed + i
        )
        for v in args.vehicles
        for f in args.flows
        for i, s in enumerate(starts)
    ]
    print(
        f"koopguide bench missions: {len(specs)} runs ({len(args.vehicles)} vehicles x {len(args.flows)} flows "
        f"x {args.starts} starts), {args.workers} workers, x{args.speedup:g}",
        file=sys.stderr,
    )
    started = time.monotonic()
    results = run_campaign(specs, args.workers)
    wall = time.monotonic() - started
    (args.output / "runs.json").write_text(json.dumps([asdict(r) for r in results], indent=1))
    position = SENSORS["sensors"]["position"]
    slowed = sum(1 for r in results if r.error is None and r.speedup < args.speedup)
    setup = (
        f"`koopguide bench missions` with model `{model.name}`: {len(specs)} simulated missions "
        f"({', '.join(args.vehicles)} x {', '.join(args.flows)} x {args.starts} starts drawn from the "
        f"demonstrations' box enlarged by 10%, seed {args.seed}), speed-up x{args.speedup:g}, {args.workers} "
        f"workers, {wall:.0f} s wall; {slowed} runs in which the simulator fell behind its pace were flown "
        f"again slower (`mission.fly_paced`).\n\nMission: goal NED (0, 0), 0.04 m per model unit, model +x East, "
        f"`max_speed` 0.3 m/s, arrival radius 0.15 m, {args.timeout_s:g} s allowed to arrive, {args.hold_s:g} s "
        f"watched after arrival. Position sensor: noise {position['noise_std_m']} m, latency "
        f"{position['latency_s']} s. Uniform currents {CURRENT_MPS} m/s toward each side; the vortex and the "
        f"double gyre as in `koopguide/harness/campaign.py` (`FLOWS`)."
    )
    campaign_report.write(args.output, results, field_, setup)
    print(f"wrote {args.output / 'report.md'} and {args.output / 'paths.png'} ({wall:.0f} s wall)", file=sys.stderr)
    return 0 if all(r.error is None for r in results) else 1


def _default_model(out: Path) -> Path:
    from koopguide.base import data
    from koopguide.model.learn.export import train_to_file

    model = out / "zshape.pt"
    if not model.is_file():
        print(f"training Zshape into {model}", file=sys.stderr)
        train_to_file(data.load_lasa("Zshape"), model, seed=0)
    return model


if __name__ == "__main__":
    sys.exit(main())
