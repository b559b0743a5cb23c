"""Simulation: scenario generators (papers 002 and 000), metrics, the runner and plots."""
