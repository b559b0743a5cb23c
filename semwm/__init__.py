"""semwm: a knowledge-driven semantic world model (Multiple Hypothesis Filter) for robots."""

__version__ = "0.1.0"
