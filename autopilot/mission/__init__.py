"""Missions: the MAVLink mission protocol, item validation, and flying the stored mission."""
