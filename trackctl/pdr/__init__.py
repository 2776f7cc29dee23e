"""Pedestrian dead reckoning from phone motion sensors: steps wherever the phone is carried."""

from trackctl.pdr.processor import PDR_PROCESSOR, PdrConfig, PdrProcessor, steps_topic
from trackctl.pdr.steps import StepConfig, StepResult, detect_steps

__all__ = [
    "PDR_PROCESSOR",
    "PdrConfig",
    "PdrProcessor",
    "StepConfig",
    "StepResult",
    "detect_steps",
    "steps_topic",
]
