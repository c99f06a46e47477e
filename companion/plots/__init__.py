"""Figures (matplotlib, optional extra ``plot``; imported lazily with a clear error when missing)."""

from companion.errors import CompanionError


def require_matplotlib():
    """Import matplotlib with the Agg backend, or raise a one-line CompanionError."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise CompanionError("plotting needs matplotlib: pip install 'companion[plot]'") from None
    return plt
