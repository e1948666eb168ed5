"""The bundled boat simulator: small surface vehicles that speak MAVLink like an ArduPilot Rover boat.

Data flow, one physics step (sitl.runner.Simulation.step), all in simulated time:

    flow (sitl.flow) --V_c(N, E, t)--> hull EoM (sitl.vessel) + actuators of the boat's kind
        (sitl.vehicles: diff_thrust, rudder, vectored) --RK4 (sitl.integrate)--> state
    state --walls (sitl.world)--> sensors (sitl.sensors) --estimate--> autopilot (sitl.autopilot:
        modes; sitl.guided: setpoint rules; sitl.steering: controllers and mixers; sitl.parameters)
    autopilot --actuator commands--> vehicle (next step)
    boat (sitl.boat) --telemetry (sitl.telemetry)--> links (sitl.mavlink_endpoint) --> clients
    clients --> links --> sitl.inbound --> autopilot (modes, arming, setpoints, parameters)
    ground truth --> sitl.recorder (JSON lines)

Entry points: ``koopguide sitl`` / ``python -m sitl`` (sitl.cli), ``python -m sitl.bench``, and for
programs ``sitl.runner.Simulation``, ``sitl.runner.SimulationThread``, ``sitl.process.SimulatorProcess``
(see docs/simulator.md).
"""
