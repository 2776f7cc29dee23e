"""Processor registry and runner (``trackctl process``)."""

from trackctl.processing.base import (
    Processor,
    ProcessorInfo,
    Progress,
    get_processor,
    processors,
    register_processor,
)
from trackctl.processing.runner import copy_log, run_processors, store_report

__all__ = [
    "Processor",
    "ProcessorInfo",
    "Progress",
    "copy_log",
    "get_processor",
    "processors",
    "register_processor",
    "run_processors",
    "store_report",
]
