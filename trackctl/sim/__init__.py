"""Scenario generators with ground truth (``trackctl simulate``)."""

from trackctl.sim.demo import DemoConfig, simulate_demo

__all__ = ["DemoConfig", "simulate_demo"]
