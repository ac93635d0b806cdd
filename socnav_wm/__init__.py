"""socnav-wm: predictive world models for social robot navigation."""

__version__ = "0.1.0"
