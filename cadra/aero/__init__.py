"""aero."""
