"""The guidance service: MAVLink in -> Kalman filter -> frame transform -> field -> speed scaling -> safety
-> SET_POSITION_TARGET_LOCAL_NED out; status -> zenoh.

Pure math lives in ``frames``, ``tracker`` and ``command``; I/O in ``link`` (MAVLink), ``status_bus``
(zenoh) and ``daemon`` (the asyncio service that joins them).
"""
