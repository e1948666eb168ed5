"""The live web dashboard (``koopguide dashboard``): server, zenoh hub, streamlines, control requests."""
