"""The paper's figures (matplotlib, the optional ``plot`` extra), one module per system."""

from __future__ import annotations

from types import ModuleType

from trackctl.errors import InputError

__all__ = ["pyplot"]


def pyplot() -> ModuleType:
    """matplotlib.pyplot on the non-interactive Agg backend.

    Raises:
        InputError: matplotlib is not installed.
    """
    try:
        import matplotlib
    except ImportError:
        raise InputError("--plot needs matplotlib: pip install 'trackctl[plot]'") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt
