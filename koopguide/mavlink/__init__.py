"""The project's one MAVLink vocabulary and transport, shared by the guidance service and the simulator.

* :mod:`~koopguide.mavlink.endpoint` - the endpoint grammar (udpin/udpout/tcpin/tcp/serial): ``Endpoint``,
  ``EndpointError``.
* :mod:`~koopguide.mavlink.rover` - ArduPilot Rover mode numbers, SET_POSITION_TARGET type masks and the
  message builders (heartbeat, set_mode, arm, message_interval, velocity_setpoint).
* :mod:`~koopguide.mavlink.wire` - the pinned MAVLink 2 ardupilotmega dialect (``mavlink``), decoders and
  the signing ``Encoder``.
* :mod:`~koopguide.mavlink.signing` - the key file (``SigningKey``) and the signature/replay check.
* :mod:`~koopguide.mavlink.intake` - per-source parsing and the link counters (``LinkStats``).
* :mod:`~koopguide.mavlink.link` - ``Link`` (opened with ``link_settings.LinkSettings``): the asyncio owner
  of one connection, with source pinning and bounded peers; :mod:`~koopguide.mavlink.datagram` (its
  exclusive UDP socket) and :mod:`~koopguide.mavlink.serial_port` (a raw serial device).

This package imports nothing from the guidance service or the simulator. Details: docs/mavlink.md.
"""
