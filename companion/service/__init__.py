"""The companion process: pipeline from MAVLink messages to health reports, and its saved state."""
